#include "organfit/pipeline/export_command.h"

#include <fmt/format.h>
#include <spdlog/spdlog.h>

#include <algorithm>
#include <memory>
#include <optional>

#include "organfit/pipeline/export_stage.h"
#include "organfit/pipeline/model_file.h"
#include "organfit/support/error.h"
#include "organfit/support/output_folder.h"

namespace fs = std::filesystem;

namespace organfit::pipeline {

nlohmann::json run_export_command(const ExportCommand& c) {
  const std::vector<fs::path> outputs = {c.rtstruct,           c.labels,   c.mesh,
                                         c.displacement_field, c.jacobian, c.registration};
  if (std::all_of(outputs.begin(), outputs.end(), [](const fs::path& f) { return f.empty(); }))
    throw InputError(
        "export: name at least one output (--rtstruct, --labels, --mesh, "
        "--displacement-field, --registration, --jacobian)");
  std::vector<fs::path> inputs = {c.model, c.ct, c.copy_rois_from};
  for (const auto& f : outputs)
    if (!f.empty())
      check_output_location(f.parent_path().empty() ? fs::path(".") : f.parent_path(), inputs,
                            "the output", OutputKind::kFile);
  const SavedModel saved = load_model(c.model);
  if (saved.ct)
    for (const auto& f : outputs)
      if (!f.empty())
        check_output_location(f.parent_path().empty() ? fs::path(".") : f.parent_path(),
                              {saved.ct->folder}, "the output", OutputKind::kFile);
  ExportRequest request;
  request.rtstruct = c.rtstruct, request.labels = c.labels, request.mesh = c.mesh;
  request.displacement_field = c.displacement_field, request.jacobian = c.jacobian;
  request.registration = c.registration;
  request.field_spacing_mm = c.field_spacing_mm;
  request.roi_name = c.roi_name.empty() ? saved.organ_name + "_fit" : c.roi_name;
  request.roi_colour = saved.organ_look.colour;
  request.roi_type = saved.organ_look.interpreted_type;
  std::optional<dicom::CtSeries> ct;
  if (request.needs_ct()) {
    if (c.ct.empty() && !saved.ct)
      throw InputError(c.model.string() + ": the model names no planning CT; give --ct");
    const fs::path folder = c.ct.empty() ? fs::path(saved.ct->folder) : c.ct;
    // The model's own series when its folder is used; a folder given with --ct must hold
    // one CT series, and it must be the model's (series and Frame of Reference).
    dicom::CtReadOptions o;
    if (saved.ct && c.ct.empty()) o.series_instance_uid = saved.ct->series_instance_uid;
    ct = dicom::read_ct_series(folder, o);
    if (saved.ct && (ct->frame_of_reference_uid != saved.ct->frame_of_reference_uid ||
                     ct->series_instance_uid != saved.ct->series_instance_uid))
      throw InputError(fmt::format(
          "{}: this CT series (or its Frame of Reference) is not the model's: the model "
          "was built on another CT",
          folder.string()));
    for (const auto& w : ct->warnings)
      spdlog::warn(w);
  }
  std::optional<dicom::StructureSet> other;
  if (!c.copy_rois_from.empty()) {
    if (c.rtstruct.empty()) throw InputError("export: --copy-rois-from needs --rtstruct");
    other = read_rois_to_copy(c.copy_rois_from, *ct);
    request.copy_rois_from = &*other;
    request.skip_roi = saved.organ_name;  // the fitted ROI replaces its source
  }
  PendingExport pending = prepare_export(organ_body(saved.model), saved.model.model->radius_mm(),
                                         ct ? &*ct : nullptr, request);
  for (const auto& w : pending.warnings)
    spdlog::warn(w);
  std::vector<std::unique_ptr<CreatedFolders>> folders;
  for (const auto& f : outputs)
    if (!f.empty() && !f.parent_path().empty())
      folders.push_back(std::make_unique<CreatedFolders>(f.parent_path()));
  pending.commit();
  for (auto& f : folders)
    f->keep();
  return pending.summary;
}

}  // namespace organfit::pipeline
