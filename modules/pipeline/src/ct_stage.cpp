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

CtStageResult run_ct_stage(const config::Scene& scene, const fs::path& staging,
                           const fs::path& out_dir, const fs::path& phantom_ct,
                           const fs::path& phantom_home) {
  CtStageResult r;
  Stopwatch clock;
  dicom::CtReadOptions o = ct_options_from(scene);
  r.folder = phantom_ct;
  r.home = phantom_home;
  if (scene.has_section("ct")) {
    if (scene.is_given("ct", "node")) {
      r.folder = staging / "cache" / "ct";
      r.home = out_dir / "cache" / "ct";
      r.pulled = pull_ct(scene, r.folder);
      o.series_instance_uid = r.pulled->series_uid;
      r.pull_wall_s = clock.elapsed_s();
      r.pull_peak_memory_mib = peak_memory_mib();
      spdlog::info("ct: {} objects pulled from {} in {:.2f} s (C-FIND {:.2f} s, C-GET {:.2f} s)",
                   r.pulled->files.size(), scene.text("ct", "node"), r.pull_wall_s,
                   r.pulled->find_s, r.pulled->get_s);
      clock.restart();
    } else {
      r.folder = scene.path("ct", "folder");
      r.home = r.folder;
    }
  }
  r.ct = dicom::read_ct_series(r.folder, o);
  r.read_wall_s = clock.elapsed_s();
  return r;
}

}  // namespace organfit::pipeline
