// `organfit export`: a saved model (planning or fitted) written for the planning system
// outside a scene: the same export stage a scene's `export` section runs.
#include <fmt/format.h>
#include <spdlog/spdlog.h>

#include <CLI/CLI.hpp>
#include <algorithm>
#include <filesystem>
#include <iostream>
#include <memory>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>

#include "commands.h"
#include "organfit/itkbridge/itk_images.h"
#include "organfit/meshing/plain_mesh.h"
#include "organfit/pipeline/export_stage.h"
#include "organfit/pipeline/model_file.h"
#include "organfit/support/error.h"
#include "organfit/support/output_folder.h"

namespace fs = std::filesystem;

namespace organfit::app {
namespace {

struct ExportCommand {
  std::filesystem::path model;  ///< model file (export.model of a scene)
  std::filesystem::path ct;     ///< planning CT folder; default: the one the model names
  std::filesystem::path rtstruct, labels, mesh;
  std::filesystem::path displacement_field, jacobian, registration;  ///< on the CT's grid
  std::filesystem::path uncertainty;     ///< sigma (mm) on the CT's grid, from a fitted model
  double field_spacing_mm = 0;           ///< their grid: 0, the CT's (ExportRequest)
  std::string roi_name;                  ///< default: the model's organ + "_fit"
  std::filesystem::path copy_rois_from;  ///< an RT Structure Set whose ROIs are copied alongside
};

/// Whether two paths name one file (through "..", symbolic links and the working folder).
bool same_place(const fs::path& a, const fs::path& b) {
  std::error_code ea, eb;
  const fs::path ca = fs::weakly_canonical(a, ea), cb = fs::weakly_canonical(b, eb);
  if (ea || eb) return fs::absolute(a).lexically_normal() == fs::absolute(b).lexically_normal();
  return ca == cb;
}

/// Runs the export; returns the summary (as run.json's "export"). Throws InputError on
/// bad input (nothing written then): no output named, a CT whose series or Frame of
/// Reference is not the model's, a model outside the CT.
nlohmann::json run_export_command(const ExportCommand& c) {
  const std::vector<fs::path> outputs = {c.rtstruct,           c.labels,   c.mesh,
                                         c.displacement_field, c.jacobian, c.registration,
                                         c.uncertainty};
  if (std::all_of(outputs.begin(), outputs.end(), [](const fs::path& f) { return f.empty(); }))
    throw InputError(
        "export: name at least one output (--rtstruct, --labels, --mesh, "
        "--displacement-field, --registration, --jacobian, --uncertainty)");
  if (const std::string why = pipeline::roi_name_problem(c.roi_name); !why.empty())
    throw InputError("--roi-name: " + why);
  // Each writer's format, before any work.
  for (const fs::path* image : {&c.labels, &c.displacement_field, &c.jacobian, &c.uncertainty})
    if (!image->empty())
      if (const std::string why = itkbridge::image_file_name_problem(*image); !why.empty())
        throw InputError(image->string() + ": " + why);
  if (!c.mesh.empty())
    if (const std::string why = meshing::mesh_file_name_problem(c.mesh.string()); !why.empty())
      throw InputError(c.mesh.string() + ": " + why);
  // Two outputs at one path: the later would replace the earlier without a word.
  const std::vector<const char*> flags = {"--rtstruct",           "--labels",   "--mesh",
                                          "--displacement-field", "--jacobian", "--registration",
                                          "--uncertainty"};
  for (size_t i = 0; i < outputs.size(); ++i)
    for (size_t j = 0; j < i; ++j)
      if (!outputs[i].empty() && !outputs[j].empty() && same_place(outputs[i], outputs[j]))
        throw InputError(
            fmt::format("{}: named by both {} and {}: each output needs a file of "
                        "its own",
                        outputs[i].string(), flags[j], flags[i]));
  std::vector<fs::path> inputs = {c.model, c.ct, c.copy_rois_from};
  for (const auto& f : outputs)
    if (!f.empty())
      check_output_location(f.parent_path().empty() ? fs::path(".") : f.parent_path(), inputs,
                            "the output", OutputKind::kFile);
  const pipeline::SavedModel saved = pipeline::load_model(c.model);
  if (const std::string w = pipeline::unchecked_model_warning(c.model, saved); !w.empty())
    spdlog::warn(w);
  if (saved.ct)
    for (const auto& f : outputs)
      if (!f.empty())
        check_output_location(f.parent_path().empty() ? fs::path(".") : f.parent_path(),
                              {saved.ct->folder}, "the output", OutputKind::kFile);
  pipeline::ExportRequest request;
  request.rtstruct = c.rtstruct, request.labels = c.labels, request.mesh = c.mesh;
  request.displacement_field = c.displacement_field, request.jacobian = c.jacobian;
  request.registration = c.registration;
  request.uncertainty = c.uncertainty;
  request.sigma = saved.uncertainty;
  if (!c.uncertainty.empty() && !saved.uncertainty)
    throw InputError(c.model.string() +
                     ": the model holds no fit's uncertainty (a planning model, or a fitted one "
                     "saved before models kept it); --uncertainty needs a session's model");
  request.field_spacing_mm = c.field_spacing_mm;
  request.roi_name = c.roi_name.empty() ? pipeline::fitted_roi_name(saved.organ_name) : c.roi_name;
  request.roi_colour = saved.organ_look.colour;
  request.roi_type = saved.organ_look.interpreted_type;
  std::optional<dicom::CtSeries> ct;
  if (request.needs_ct()) {
    if (c.ct.empty() && !saved.ct)
      throw InputError(c.model.string() + ": the model names no planning CT; give --ct");
    const fs::path folder = c.ct.empty() ? fs::path(saved.ct->folder) : c.ct;
    std::error_code gone;
    if (c.ct.empty() && !fs::is_directory(folder, gone))
      throw InputError(fmt::format(
          "{}: the planning CT it records, {}, is not there: give --ct (where that CT is now)",
          c.model.string(), folder.string()));
    // The model's own series when its folder is used; of a folder given with --ct, its one
    // CT series, or of several the model's, and it must be the model's (series and Frame
    // of Reference).
    dicom::CtReadOptions o;
    if (saved.ct && c.ct.empty()) o.series_instance_uid = saved.ct->series_instance_uid;
    if (saved.ct && !c.ct.empty()) {
      o.referenced_series_uids = {saved.ct->series_instance_uid};
      o.referenced_by = "the model";
    }
    ct = dicom::read_ct_series(folder, o);
    if (!ct->choice.empty()) spdlog::info("ct: {}", ct->choice);
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
    other = pipeline::read_rois_to_copy(c.copy_rois_from, *ct);
    request.copy_rois_from = &*other;
    request.skip_roi = saved.organ_name;  // the fitted ROI replaces its source
  }
  pipeline::PendingExport pending =
      prepare_export(fitting::organ_body(saved.model), saved.model.model->radius_mm(),
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

}  // namespace

Command add_export(CLI::App& app) {
  auto exp = std::make_shared<ExportCommand>();
  auto* export_cmd = app.add_subcommand(
      "export", "Write a saved model for the planning system: RTSTRUCT, label map, mesh");
  export_cmd->add_option("--model", exp->model, "Model file (a scene's export.model)")->required();
  export_cmd->add_option("--ct", exp->ct,
                         "Planning CT folder (default: the one the model was built on)");
  export_cmd->add_option("--rtstruct", exp->rtstruct, "RT Structure Set to write (.dcm)");
  export_cmd->add_option("--labels", exp->labels,
                         "Label map to write (.nrrd, .mha, .nii, .nii.gz)");
  export_cmd->add_option("--mesh", exp->mesh, "Surface mesh to write (.stl, .vtp, .ply, .obj)");
  export_cmd->add_option("--displacement-field", exp->displacement_field,
                         "Deformation field to write on the planning CT's grid (.mha, .nrrd): "
                         "phi^-1(q) - q, as plastimatch warp --xf reads it");
  export_cmd->add_option("--registration", exp->registration,
                         "DICOM Deformable Spatial Registration (REG) to write: the same field");
  export_cmd
      ->add_option("--field-spacing", exp->field_spacing_mm,
                   "Grid of the field, REG and Jacobian (mm; 0: the CT's grid)")
      ->check(CLI::Range(0.0, 50.0));
  export_cmd->add_option("--jacobian", exp->jacobian,
                         "det(grad phi) to write on the planning CT's grid (.nrrd, .mha)");
  export_cmd->add_option("--uncertainty", exp->uncertainty,
                         "The fit's uncertainty to write on the planning CT's grid (.nrrd, "
                         ".mha): each voxel to sigma (mm) of the surface there; a fitted "
                         "model's");
  export_cmd->add_option("--roi-name", exp->roi_name,
                         "Name of the exported ROI (default: the organ's name + _fit)");
  export_cmd->add_option("--copy-rois-from", exp->copy_rois_from,
                         "RT Structure Set whose other ROIs are copied alongside");
  return {export_cmd, [exp] {
            std::cout << run_export_command(*exp).dump() << "\n";
            return 0;
          }};
}

}  // namespace organfit::app
