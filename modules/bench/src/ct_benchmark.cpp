#include "organfit/bench/ct_benchmark.h"

#include <fmt/format.h>
#include <unistd.h>

#include <algorithm>
#include <cstdlib>

#include "organfit/pipeline/phantom_stage.h"
#include "organfit/pipeline/runner.h"
#include "organfit/pipeline/scene_schema.h"
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
  const std::string scene_text = fmt::format(
      "scene:\n  name: bench-ct\n  threads: {}\nct:\n  folder: '{}'\norgan:\n  source: seed\n  "
      "roi: organ\n"
      "  seed_mm: [{}, {}, {}]\n  hu_low: {}\n  hu_high: {}\nmodel:\n  radius_mm: {}\n",
      o.threads, fs::absolute(ct).string(), o.seed_mm[0], o.seed_mm[1], o.seed_mm[2],
      o.hu_window[0], o.hu_window[1], o.radius_mm);
  const config::Scene scene =
      config::parse_scene(scene_text, work / "bench-ct.yaml", pipeline::scene_schema());
  pipeline::check_scene_rules(scene);
  const nlohmann::json run = pipeline::run_scene(scene, work / "out");

  nlohmann::json stages = nlohmann::json::object();
  double total = 0;
  for (const auto& st : run["stages"]) {
    stages[st["name"].get<std::string>()] = st["wall_s"];
    total += st["wall_s"].get<double>();
  }
  const auto& m = run["model"];
  return {{"benchmark", "ct"},
          {"ct", run["ct"]},
          {"phantom_made_s", synth_s},
          {"threads", run["threads"]},
          {"organ_volume_cm3", run["organ"]["volume_cm3"]},
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
