#pragma once
// `organfit run`: runs the stages a scene names, in order, and writes run.json and
// resolved.yaml into the output folder. Outputs appear only when the run completes.
#include <filesystem>
#include <nlohmann/json.hpp>

#include "organfit/config/scene.h"

namespace organfit::pipeline {

/// The organfit version string ("0.1.0").
const char* version();

/// The stages of a full session, in order, and whether this build has them.
struct StageInfo {
  const char* name;
  bool available;
};
const std::vector<StageInfo>& pipeline_stages();

/// Runs the scene into `out_dir` (created if needed; must not be the scene's folder).
/// Returns the run.json content it wrote. Throws organfit::Error on bad input (2) or
/// an unmet target (3); nothing with a final name is left behind on failure.
struct RunOptions {
  /// Patient name, ID and birth date may appear in the report (the scene's
  /// report.show_patient asks for them). Off: they appear in no output and no log.
  bool show_phi = false;
};

nlohmann::json run_scene(const config::Scene& scene, const std::filesystem::path& out_dir,
                         const RunOptions& options = {});

}  // namespace organfit::pipeline
