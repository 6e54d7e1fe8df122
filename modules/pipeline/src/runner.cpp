#include "organfit/pipeline/runner.h"

#include <omp.h>
#include <spdlog/spdlog.h>

#include "organfit/pipeline/model_stage.h"
#include "organfit/support/atomic_file.h"
#include "organfit/support/error.h"
#include "organfit/support/resources.h"

namespace fs = std::filesystem;

namespace organfit::pipeline {

const char* version() { return ORGANFIT_VERSION; }

const std::vector<StageInfo>& pipeline_stages() {
  static const std::vector<StageInfo> stages = {
      {"ct", false},  {"organ", false},  {"model", true},  {"ultrasound", false},
      {"fit", false}, {"export", false}, {"report", false}};
  return stages;
}

namespace {

void prepare_output_folder(const config::Scene& scene, const fs::path& out_dir) {
  std::error_code ec;
  if (fs::exists(out_dir, ec) && !fs::is_directory(out_dir, ec)) {
    throw InputError(out_dir.string() + ": --out exists and is not a folder");
  }
  const fs::path scene_dir = fs::absolute(scene.file()).parent_path();
  if (fs::exists(out_dir, ec) && fs::equivalent(out_dir, scene_dir, ec)) {
    throw InputError(out_dir.string() +
                     ": --out is the scene's own folder; choose a separate output folder so "
                     "inputs are never overwritten");
  }
  fs::create_directories(out_dir, ec);
  if (ec) throw InputError(out_dir.string() + ": cannot create the output folder: " + ec.message());
}

}  // namespace

nlohmann::json run_scene(const config::Scene& scene, const fs::path& out_dir) {
  prepare_output_folder(scene, out_dir);
  const long long threads = scene.integer("scene", "threads");
  if (threads > 0) omp_set_num_threads(static_cast<int>(threads));

  std::string name = scene.text("scene", "name");
  if (name.empty()) name = scene.file().stem().string();
  nlohmann::json run = {{"organfit_version", version()},
                        {"scene", {{"name", name}, {"file", fs::absolute(scene.file()).string()}}},
                        {"threads", omp_get_max_threads()},
                        {"stages", nlohmann::json::array()},
                        {"warnings", nlohmann::json::array()},
                        {"outputs", nlohmann::json::array()}};
  Stopwatch total;
  auto record_stage = [&](const char* stage, double wall_s) {
    run["stages"].push_back(
        {{"name", stage}, {"wall_s", wall_s}, {"peak_memory_mib", peak_memory_mib()}});
  };

  std::vector<std::string> skipped;
  for (const auto& stage : pipeline_stages()) {
    if (!stage.available) skipped.push_back(stage.name);
  }

  if (scene.has_section("model")) {
    Stopwatch clock;
    ModelStageResult model = run_model_stage(scene);
    record_stage("model", clock.elapsed_s());
    run["model"] = model.summary;
    spdlog::info("model: {} particles, relaxed in {} steps ({:.2f} s), skeleton {:.2f} s",
                 model.state.size(), model.summary["relax_steps"].get<long long>(),
                 model.summary["relax_wall_s"].get<double>(),
                 model.summary["skeleton_wall_s"].get<double>());
    if (!model.summary["relax_settled"].get<bool>()) {
      const std::string w = "model: relaxation did not settle within model.relax_steps";
      spdlog::warn(w);
      run["warnings"].push_back(w);
    }
  } else {
    spdlog::info("the scene names no stage this version can run (model)");
  }
  if (!skipped.empty()) {
    std::string list;
    for (const auto& s : skipped) list += (list.empty() ? "" : ", ") + s;
    spdlog::info("not built yet in organfit {}: the {} stages; this run did what exists",
                 version(), list);
    run["stages_not_built_yet"] = skipped;
  }

  run["wall_s"] = total.elapsed_s();
  run["peak_memory_mib"] = peak_memory_mib();
  run["outputs"] = {"resolved.yaml", "run.json"};
  run["status"] = "ok";
  // Both files are committed only now: a failed run leaves neither.
  write_file_atomically(out_dir / "resolved.yaml", scene.resolved_yaml());
  write_file_atomically(out_dir / "run.json", run.dump(2) + "\n");
  return run;
}

}  // namespace organfit::pipeline
