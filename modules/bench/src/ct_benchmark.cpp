#include "organfit/bench/ct_benchmark.h"

#include <fmt/format.h>
#include <omp.h>
#include <unistd.h>

#include <algorithm>
#include <cstdlib>

#include "organfit/pipeline/ct_stage.h"
#include "organfit/pipeline/model_stage.h"
#include "organfit/pipeline/organ_stage.h"
#include "organfit/pipeline/phantom_stage.h"
#include "organfit/support/error.h"
#include "organfit/support/interrupt.h"
#include "organfit/support/resources.h"

namespace fs = std::filesystem;

namespace organfit::bench {

nlohmann::json run_ct_benchmark(const CtBenchOptions& o) {
  if (o.seed_mm.size() != 3 || o.hu_window.size() != 2)
    throw InputError("bench ct: --seed takes X,Y,Z and --hu LO,HI");
  const fs::path work = fs::temp_directory_path() / fmt::format("organfit_bench_ct_{}", getpid());
  fs::remove_all(work);
  fs::create_directories(work);
  struct Cleanup {
    fs::path dir;
    ~Cleanup() {
      std::error_code ec;
      fs::remove_all(dir, ec);
    }
  } cleanup{work};
  const PartialPath partial(work);  // removed too if the process is stopped

  fs::path ct = o.ct;
  double synth_s = 0;
  if (ct.empty()) {
    // In this process, as `organfit synth pelvis` makes it: a child process stopped with
    // this one could outlive it and write into the work folder after it was removed.
    Stopwatch clock;
    phantom::PelvisOptions pelvis;
    pelvis.columns = o.columns, pelvis.rows = o.rows, pelvis.slices = o.slices;
    pelvis.pixel_mm = 400.0 / std::max(o.columns, o.rows);
    pipeline::write_pelvis_phantom(work / "phantom", pelvis);
    synth_s = clock.elapsed_s();
    ct = work / "phantom" / "ct";
  }
  if (o.threads > 0) omp_set_num_threads(o.threads);
  // The stages a planning run calls, in turn: read the CT, grow the organ, fill and relax
  // its model (a folder read needs neither staging nor --out: the work folder stands in).
  nlohmann::json stages = nlohmann::json::object();
  double total = 0;
  auto timed = [&](const char* stage, auto&& call) {
    Stopwatch clock;
    auto result = call();
    stages[stage] = clock.elapsed_s();
    total += clock.elapsed_s();
    throw_if_interrupted();
    return result;
  };
  pipeline::CtStageOptions ct_options;
  ct_options.folder = fs::absolute(ct);
  const pipeline::CtStageResult read = timed(
      "ct", [&] { return pipeline::run_ct_stage(ct_options, work / "staging", work, {}, {}); });
  pipeline::OrganStageOptions organ_options;
  organ_options.roi = "organ";
  organ_options.seed.emplace();
  organ_options.seed->seed_mm = Eigen::Vector3d(o.seed_mm[0], o.seed_mm[1], o.seed_mm[2]);
  organ_options.seed->hu_low = o.hu_window[0], organ_options.seed->hu_high = o.hu_window[1];
  const pipeline::OrganStageResult organ = timed("organ", [&] {
    return pipeline::run_organ_stage(organ_options, read.ct, {}, work / "staging", work);
  });
  pipeline::ModelStageOptions model_options;
  model_options.settings.radius_mm = o.radius_mm;
  const pipeline::ModelStageResult model =
      timed("model", [&] { return pipeline::run_model_stage(model_options, &organ.shape); });
  const auto& g = read.ct.geometry;
  const nlohmann::json ct_summary = {
      {"slices", g.size[2]},
      {"size", {g.size[0], g.size[1], g.size[2]}},
      {"spacing_mm", {g.spacing_mm.x(), g.spacing_mm.y(), g.spacing_mm.z()}}};
  const nlohmann::json& m = model.summary;
  return {{"benchmark", "ct"},
          {"ct", ct_summary},
          {"phantom_made_s", synth_s},
          {"threads", omp_get_max_threads()},
          {"organ_volume_cm3", organ.summary["volume_cm3"]},
          {"particles", m["particles"]},
          {"skeleton_nodes", m["skeleton_nodes"]},
          {"skeleton_from", m["skeleton_from"]},
          {"model_volume_vs_organ_pct", m["volume_vs_reference_pct"]},
          {"stage_wall_s", stages},
          {"skeleton_wall_s", m["skeleton_wall_s"]},
          {"read_segment_skeleton_seed_s", total},
          {"target_s", o.target_s},
          {"meets_target", total <= o.target_s},
          {"peak_memory_mib", peak_memory_mib()}};
}

}  // namespace organfit::bench
