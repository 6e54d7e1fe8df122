#pragma once
// `organfit export`: a saved model (planning or fitted) written for the planning system
// outside a scene: the same export stage a scene's `export` section runs.
#include <filesystem>
#include <nlohmann/json.hpp>
#include <string>

namespace organfit::pipeline {

struct ExportCommand {
  std::filesystem::path model;  ///< model file (export.model of a scene)
  std::filesystem::path ct;     ///< planning CT folder; default: the one the model names
  std::filesystem::path rtstruct, labels, mesh;
  std::filesystem::path displacement_field, jacobian, registration;  ///< on the CT's grid
  double field_spacing_mm = 0;           ///< their grid: 0, the CT's (ExportRequest)
  std::string roi_name;                  ///< default: the model's organ + "_fit"
  std::filesystem::path copy_rois_from;  ///< an RT Structure Set whose ROIs are copied alongside
};

/// Runs the export; returns the summary (as run.json's "export"). Throws InputError on
/// bad input (nothing written then): no output named, a CT whose series or Frame of
/// Reference is not the model's, a model outside the CT.
nlohmann::json run_export_command(const ExportCommand& command);

}  // namespace organfit::pipeline
