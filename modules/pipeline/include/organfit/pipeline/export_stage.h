#pragma once
// The export stage: a (fitted) particle model written for the planning system. What is
// written is the organ the model carries: its reference body (the planning organ) moved
// with the particles (fitting/embedded_body.h); at rest, the planning organ itself.
//   rtstruct  a DICOM RT Structure Set on the planning CT: that organ on the CT grid,
//             contoured slice by slice; optionally the input structure set's other ROIs
//             copied alongside
//   labels    the same mask as a label map (NRRD, MHA, NIfTI) with the CT's geometry
//   mesh      the body's surface (STL, VTP, PLY, OBJ), independent of the CT grid
//   displacement_field  the deformation on the planning CT's grid, as plastimatch's
//             `warp --xf` reads it: at each voxel q (today), v(q) = phi^-1(q) - q (mm,
//             the CT's patient frame, LPS), the planning point it came from less q; so
//             warping the planning CT (or its dose, or its label map) by it gives today's
//   registration  the same vectors as a DICOM Deformable Spatial Registration on the
//             planning CT's Frame of Reference (dicom/registration_writer.h)
//   jacobian  det(grad phi) at each voxel of the planning CT's grid: the volume today of
//             the tissue now there over its planning volume (1 where phi keeps volume)
// The field, REG and Jacobian are on the CT's grid, or a coarser one over its box
// (field_spacing_mm); plastimatch then warps onto the CT's grid with `--fixed CT`.
// Checks, in the summary and as warnings: the exported organ has the planning organ's
// components and cavities (geometry/topology.h), and its volume on the CT grid is the
// planning organ's times the deformation's volume change (within 0.5% and the grid's
// sampling, 3 sigma).
// Everything is computed first; files are written only by commit(), each atomically,
// so a failure leaves no partial output.
#include <array>
#include <filesystem>
#include <functional>
#include <memory>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <vector>

#include "organfit/config/scene.h"
#include "organfit/dicom/ct_series.h"
#include "organfit/dicom/structure_set.h"
#include "organfit/fitting/embedded_body.h"
#include "organfit/fitting/surface_uncertainty.h"
#include "organfit/particles/state.h"
#include "organfit/pipeline/model_file.h"

namespace organfit::pipeline {

struct ExportRequest {
  std::filesystem::path rtstruct, labels, mesh;        ///< empty: not written
  std::filesystem::path displacement_field, jacobian;  ///< empty: not written
  std::filesystem::path registration;                  ///< DICOM REG; empty: not written
  std::filesystem::path uncertainty;  ///< sigma (mm) on the CT's grid; empty: not written
  /// The fit's uncertainty: written as `uncertainty`, and as the mesh's sigma_mm points.
  std::shared_ptr<const fitting::SurfaceUncertainty> sigma;
  /// The grid of the displacement field, REG and Jacobian: 0, the planning CT's; else one
  /// of this spacing (mm) on every axis over the CT's box (its origin and axes).
  double field_spacing_mm = 0;
  std::string roi_name;                        ///< the fitted organ's ROI
  std::array<int, 3> roi_colour{0, 200, 255};  ///< its ROI Display Color (R, G, B)
  /// its RT ROI Interpreted Type; one that is not a DICOM code string (A-Z, 0-9, space,
  /// underscore; 16 characters) is written as ORGAN
  std::string roi_type = "ORGAN";
  /// ROIs to copy into the RT Structure Set beside the fitted one (from the input one).
  const dicom::StructureSet* copy_rois_from = nullptr;
  std::string skip_roi;     ///< not copied (the organ the fit replaces is kept under its own name)
  bool fixed_uids = false;  ///< deterministic UIDs and dates (tests)

  /// Files written on the planning CT's grid (an RT Structure Set, a label map; the
  /// uncertainty) and files of the deformation on it or over its box: each needs the
  /// planning CT. The first two are made from the organ on its grid.
  bool on_ct_grid() const { return !rtstruct.empty() || !labels.empty(); }
  bool deformation_files() const {
    return !displacement_field.empty() || !registration.empty() || !jacobian.empty();
  }
  bool needs_ct() const { return on_ct_grid() || deformation_files() || !uncertainty.empty(); }
  /// Any file made from the organ or its deformation (the model file is not).
  bool writes_organ() const { return needs_ct() || !mesh.empty(); }
};

class PendingExport {
 public:
  nlohmann::json summary;          ///< run.json "export"; the mesh adds its report on commit
  std::vector<std::string> files;  ///< what commit() will write
  std::vector<std::string> warnings;
  /// The organ the files are made from, on the planning CT's grid and on the mesh's grid
  /// of rho (null when not exported): the report shows these same masks.
  std::shared_ptr<const geometry::LabelVolume> organ_on_ct, organ_on_mesh_grid;
  /// Writes the files. Throws InputError naming a file that cannot be written.
  void commit();

 private:
  friend PendingExport prepare_export(const fitting::EmbeddedBody&, double, const dicom::CtSeries*,
                                      const ExportRequest&);
  std::vector<std::function<void(nlohmann::json& summary)>> writes_;
};

/// The structure set whose ROIs an export copies beside the fitted one (the fitted ROI's
/// source is not among them: the fitted ROI replaces it), each ROI checked to be of this
/// CT (patient, study, Frame of Reference). Throws InputError naming `file`.
dicom::StructureSet read_rois_to_copy(const std::filesystem::path& file, const dicom::CtSeries& ct);

/// Computes the exports of the organ a model carries (fitting::organ_body), whose
/// particles have radius `rho_mm` (the mesh's voxel). `ct` is needed for the RT
/// Structure Set and the label map (InputError otherwise).
PendingExport prepare_export(const fitting::EmbeddedBody& organ, double rho_mm,
                             const dicom::CtSeries* ct, const ExportRequest& request);

/// DICOM's bound on a ROI Name (VR LO), in characters.
inline constexpr int kRoiNameCharacters = 64;

/// The exported ROI's name when none is given: the organ's + "_fit", the organ's cut at a
/// character (UTF-8) so that the whole is at most kRoiNameCharacters (a 63-character organ
/// name had given a 67-character ROI Name, which dciodvfy flags and a planning system may
/// cut or refuse).
std::string fitted_roi_name(const std::string& organ_name);

/// Why `name` cannot be a ROI Name, or empty when it can: more than kRoiNameCharacters
/// characters, a backslash (DICOM's separator of values) or a control character.
std::string roi_name_problem(const std::string& name);

/// The scene's `export` section as a request: each file key under `staging` (empty: not
/// written), the ROI named `organ_name` + "_fit" unless export.roi_name says otherwise,
/// in the source ROI's colour and type unless export.roi_color is given. `sigma` and the
/// ROIs to copy are the caller's to set.
ExportRequest export_request_from(const config::Scene& scene, const std::filesystem::path& staging,
                                  const std::string& organ_name, const OrganLook& look);

}  // namespace organfit::pipeline
