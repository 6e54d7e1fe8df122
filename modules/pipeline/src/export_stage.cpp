#include "organfit/pipeline/export_stage.h"

#include <fmt/format.h>

#include <algorithm>

#include "organfit/dicom/rtstruct_writer.h"
#include "organfit/geometry/mask_ops.h"
#include "organfit/geometry/slice_contours.h"
#include "organfit/itkbridge/itk_images.h"
#include "organfit/meshing/surface.h"
#include "organfit/support/error.h"
#include "organfit/support/progress.h"

namespace organfit::pipeline {

void PendingExport::commit() {
  for (auto& write : writes_)
    write(summary);
  writes_.clear();
}

namespace {
/// An RT ROI Interpreted Type as read, if it is a DICOM code string (A-Z, 0-9, space,
/// underscore; at most 16 characters), else ORGAN.
std::string type_or_organ(const std::string& type) {
  const bool code_string =
      !type.empty() && type.size() <= 16 && std::all_of(type.begin(), type.end(), [](char ch) {
        return (ch >= 'A' && ch <= 'Z') || (ch >= '0' && ch <= '9') || ch == ' ' || ch == '_';
      });
  return code_string ? type : "ORGAN";
}
}  // namespace

dicom::StructureSet read_rois_to_copy(const std::filesystem::path& file,
                                      const dicom::CtSeries& ct) {
  dicom::StructureSet set = dicom::read_rtstruct(file);
  for (const auto& roi : set.rois)
    dicom::check_structure_set_matches_ct(set, roi, ct, file.string());
  return set;
}

PendingExport prepare_export(const fitting::EmbeddedBody& organ, double rho,
                             const dicom::CtSeries* ct, const ExportRequest& r) {
  PendingExport out;
  out.summary = nlohmann::json::object();
  const bool on_ct = !r.rtstruct.empty() || !r.labels.empty();
  Progress progress("export", (on_ct ? 2 : 0) + (r.mesh.empty() ? 0 : 1));
  if (on_ct) {
    if (!ct) throw InputError("export: an RT Structure Set or label map needs the planning CT");
    auto mask = std::make_shared<geometry::LabelVolume>(organ.on_grid(ct->geometry));
    progress.update(1, "the organ on the planning CT's grid");
    out.organ_on_ct = mask;
    if (mask->count(1) == 0)
      throw InputError("export: the model lies outside the planning CT's grid");
    auto contours = geometry::slice_contours(*mask, 1);
    progress.update(2, "its contours");
    out.summary["roi"] = r.roi_name;
    out.summary["contours"] = contours.size();
    out.summary["volume_on_ct_grid_cm3"] = mask->volume_mm3(1) / 1000.0;
    if (!r.rtstruct.empty()) {
      auto rois = std::make_shared<std::vector<dicom::RtstructRoi>>();
      rois->push_back({r.roi_name, r.roi_colour, std::move(contours), type_or_organ(r.roi_type)});
      out.summary["roi_colour"] = r.roi_colour;
      out.summary["roi_interpreted_type"] = rois->back().interpreted_type;
      nlohmann::json copied = nlohmann::json::array();
      if (r.copy_rois_from) {
        for (const auto& roi : r.copy_rois_from->rois) {
          if (roi.name == r.skip_roi || roi.name == r.roi_name) continue;
          dicom::RoiOnSlices placed = dicom::roi_on_slices(roi, *ct);
          if (placed.skipped > 0)
            out.warnings.push_back(fmt::format(
                "export: ROI '{}': {} contour(s) not copied (not CLOSED_PLANAR or on no "
                "slice of the CT)",
                roi.name, placed.skipped));
          if (placed.contours.empty()) continue;
          dicom::RtstructRoi copy{roi.name, roi.colour, std::move(placed.contours),
                                  type_or_organ(roi.interpreted_type)};
          copy.generation_algorithm = "";  // copied: not ours to call AUTOMATIC
          rois->push_back(std::move(copy));
          copied.push_back(roi.name);
        }
      }
      out.summary["copied_rois"] = copied;
      out.files.push_back(r.rtstruct.filename().string());
      const std::filesystem::path file = r.rtstruct;
      dicom::RtstructWriteOptions options;
      options.fixed_uids_and_dates = r.fixed_uids;
      out.writes_.push_back([file, rois, ct, options](nlohmann::json&) {
        dicom::write_rtstruct(file, *ct, *rois, options);
      });
    }
    if (!r.labels.empty()) {
      out.files.push_back(r.labels.filename().string());
      const std::filesystem::path file = r.labels;
      out.writes_.push_back(
          [file, mask](nlohmann::json&) { itkbridge::write_label_volume(file, *mask); });
    }
  }
  if (!r.mesh.empty()) {
    // The organ on a grid of rho, independent of the CT: windowed-sinc smoothing removes
    // the voxel steps.
    const geometry::ImageGeometry fine = geometry::grid_covering(organ.bounds(), rho, rho);
    auto body = std::make_shared<geometry::LabelVolume>(organ.on_grid(fine));
    progress.update(on_ct ? 3 : 1, "the organ on the mesh's grid");
    out.organ_on_mesh_grid = body;
    out.summary["model_volume_mm3"] = body->volume_mm3(1);
    out.files.push_back(r.mesh.filename().string());
    const std::filesystem::path file = r.mesh;
    out.writes_.push_back([file, body](nlohmann::json& summary) {
      const meshing::SurfaceReport m = meshing::write_surface(*body, file);
      summary["mesh"] = {{"file", file.filename().string()},
                         {"triangles", m.triangles},
                         {"boundary_edges", m.boundary_edges},
                         {"non_manifold_edges", m.non_manifold_edges},
                         {"outward", m.outward},
                         {"enclosed_volume_mm3", m.enclosed_volume_mm3},
                         {"area_mm2", m.area_mm2}};
    });
  }
  return out;
}

}  // namespace organfit::pipeline
