#pragma once
// The planning model on disk: built once from the planning CT, loaded by each session.
//
// One JSON file (`format: organfit-model`, `format_version: 1`) holding everything a
// session and an export need and nothing that identifies the patient:
//   settings      the model section it was built with (ModelSettings, scene key names)
//   organ         its name (the ROI) and volume
//   shape         what the particles stand for: an analytic body, or the organ's mask
//                 (cropped to the organ, run-length encoded) on the CT grid
//   lattice_spacing_mm, positions_mm (x0, y0, z0, x1, ...), skeleton nodes
//   ct            the planning CT's folder, Series Instance UID and Frame of Reference
//                 UID (export re-reads the CT there and checks the UIDs)
//   embedding     a fitted model's: how its reference follows the particles
//   uncertainty   a fitted model's: what its posterior is given (surface_uncertainty.h):
//                 the options, the attractive points, the fit's residuals there and the
//                 prior's variance field, so that an export from the file writes the
//                 run's sigma exactly (null: a planning model, or none computed)
//   provenance    organfit version, scene, date, and the planning run's stage times
//   checksum      last: 16 hexadecimal digits, a hash of the file's text before it
//                 (geometry::hash_bytes). A file changed after it was written is refused;
//                 one written before the checksum was kept is read with a warning.
// Positions are written with full double precision: a loaded model is the saved one.
#include <array>
#include <filesystem>
#include <memory>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>

#include "organfit/fitting/surface_uncertainty.h"
#include "organfit/pipeline/model_stage.h"

namespace organfit::pipeline {

struct CtReference {
  std::string folder;  ///< absolute path when saved
  std::string series_instance_uid, frame_of_reference_uid;
  /// The RT Structure Set the organ was imported from (absolute path; empty: grown from a
  /// seed): a session copies its other ROIs from it (export.copy_other_rois).
  std::string structure_set;
};

/// The organ as a structure set shows it: the exported ROI keeps the source ROI's colour
/// and RT ROI Interpreted Type (an organ grown from a seed: cyan, ORGAN).
struct OrganLook {
  std::array<int, 3> colour{0, 200, 255};
  std::string interpreted_type = "ORGAN";
};

struct SavedModel {
  ModelStageResult model;  ///< state, force terms (cohesion, skeleton), shape, reference
  std::string organ_name;  ///< e.g. Prostate
  OrganLook organ_look;
  std::optional<CtReference> ct;
  nlohmann::json provenance;
  /// the fit's uncertainty, rebuilt from the file (null: none saved)
  std::shared_ptr<const fitting::SurfaceUncertainty> uncertainty;
  /// The file's checksum was there and matched its content; false for a file written
  /// before organfit kept one (read as it is: unchecked_model_warning says so).
  bool checksum_verified = false;
};

/// The warning for a model file read without a checksum (empty when it had one).
std::string unchecked_model_warning(const std::filesystem::path& file, const SavedModel& saved);

/// Writes the model (atomically). `organ_name` names the organ for exports; `uncertainty`
/// (optional) is the fit's.
void save_model(const std::filesystem::path& file, const ModelStageResult& model,
                const std::string& organ_name, const OrganLook& look,
                const std::optional<CtReference>& ct, const nlohmann::json& provenance,
                const fitting::SurfaceUncertainty* uncertainty = nullptr);

/// Reads a model file and rebuilds its force terms. Throws InputError "FILE: reason" on
/// a file that is not an organfit model, of another format version, changed after it was
/// written (its checksum), or inconsistent (counts, non-finite positions, bad settings).
SavedModel load_model(const std::filesystem::path& file);

}  // namespace organfit::pipeline
