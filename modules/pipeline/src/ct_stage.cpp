#include "organfit/pipeline/ct_stage.h"

#include <spdlog/spdlog.h>

#include "organfit/support/resources.h"

namespace fs = std::filesystem;

namespace organfit::pipeline {

dicom::CtReadOptions ct_options_from(const config::Scene& scene) {
  dicom::CtReadOptions o;
  if (scene.has_section("ct")) {
    o.series_instance_uid = scene.text("ct", "series_uid");
    o.series_description = scene.text("ct", "series_description");
  }
  return o;
}

CtStageOptions ct_stage_options_from(const config::Scene& scene) {
  CtStageOptions o;
  o.read = ct_options_from(scene);
  if (scene.has_section("ct")) {
    if (scene.is_given("ct", "node"))
      o.pull = ct_pull_options_from(scene);
    else
      o.folder = scene.path("ct", "folder");
  }
  return o;
}

CtStageResult run_ct_stage(const CtStageOptions& options, const fs::path& staging,
                           const fs::path& out_dir, const fs::path& phantom_ct,
                           const fs::path& phantom_home) {
  CtStageResult r;
  Stopwatch clock;
  dicom::CtReadOptions o = options.read;
  r.folder = phantom_ct;
  r.home = phantom_home;
  if (options.pull) {
    r.folder = staging / "cache" / "ct";
    r.home = out_dir / "cache" / "ct";
    r.pulled = pull_ct(*options.pull, r.folder);
    o.series_instance_uid = r.pulled->series_uid;
    r.pull_wall_s = clock.elapsed_s();
    r.pull_peak_memory_mib = peak_memory_mib();
    spdlog::info("ct: {} objects pulled from {} in {:.2f} s (C-FIND {:.2f} s, C-GET {:.2f} s)",
                 r.pulled->files.size(), options.pull->node, r.pull_wall_s, r.pulled->find_s,
                 r.pulled->get_s);
    clock.restart();
  } else if (options.folder) {
    r.folder = *options.folder;
    r.home = r.folder;
  }
  r.ct = dicom::read_ct_series(r.folder, o);
  r.read_wall_s = clock.elapsed_s();
  return r;
}

}  // namespace organfit::pipeline
