#include "organfit/pipeline/runner.h"

#include <fmt/format.h>
#include <omp.h>
#include <spdlog/spdlog.h>

#include <functional>
#include <optional>
#include <set>

#include "organfit/dicom/structure_set.h"
#include "organfit/itkbridge/itk_images.h"
#include "organfit/pipeline/ct_stage.h"
#include "organfit/pipeline/export_stage.h"
#include "organfit/pipeline/fit_stage.h"
#include "organfit/pipeline/model_file.h"
#include "organfit/pipeline/model_stage.h"
#include "organfit/pipeline/node_stage.h"
#include "organfit/pipeline/organ_stage.h"
#include "organfit/pipeline/phantom_stage.h"
#include "organfit/pipeline/report_stage.h"
#include "organfit/pipeline/scene_schema.h"
#include "organfit/pipeline/ultrasound_stage.h"
#include "organfit/support/atomic_file.h"
#include "organfit/support/error.h"
#include "organfit/support/output_folder.h"
#include "organfit/support/resources.h"

namespace fs = std::filesystem;

namespace organfit::pipeline {

const char* version() {
  return ORGANFIT_VERSION;
}

const std::vector<StageInfo>& pipeline_stages() {
  static const std::vector<StageInfo> stages = {
      {"phantom", true},    {"ct", true},  {"organ", true},  {"model", true}, {"points", true},
      {"ultrasound", true}, {"fit", true}, {"export", true}, {"report", true}};
  return stages;
}

namespace {

/// Every input the scene names (the scene file, each given file or folder key), which
/// --out may not be, hold or lie in (see check_output_location).
std::vector<fs::path> scene_inputs(const config::Scene& scene) {
  std::vector<fs::path> inputs = {scene.file()};
  for (const auto& spec : scene.schema().params())
    if (spec.type == config::ParamType::kInputPath && scene.has_section(spec.section) &&
        scene.is_given(spec.section, spec.name))
      inputs.push_back(scene.path(spec.section, spec.name));
  return inputs;
}

/// The entries of --out a run of this scene writes (a folder ends in '/').
std::set<std::string> names_written(const config::Scene& scene) {
  std::set<std::string> names;
  for (const SceneOutput& o : scene_outputs(scene))
    names.insert(o.name);
  return names;
}

}  // namespace

namespace {

/// The run, its outputs (`names`, as names_written gives them) written under `output`'s
/// staging folder and moved into --out at the end.
nlohmann::json run_into(const config::Scene& scene, const fs::path& out_dir,
                        const RunOptions& run_options, const std::set<std::string>& names,
                        OutputFolder& output) {
  std::error_code ec;
  const fs::path& staging = output.staging();
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
  auto record_stage = [&run](const char* stage_name, double wall_s, double peak_mib = -1) {
    run["stages"].push_back({{"name", stage_name},
                             {"wall_s", wall_s},
                             {"peak_memory_mib", peak_mib >= 0 ? peak_mib : peak_memory_mib()}});
  };

  std::vector<std::string> skipped;
  for (const auto& s : pipeline_stages()) {
    if (!s.available) skipped.push_back(s.name);
  }

  auto warn = [&](const std::string& w) {
    spdlog::warn(w);
    run["warnings"].push_back(w);
  };
  std::optional<ModelStageResult> model;
  std::string organ_name = scene.has_section("organ") ? scene.text("organ", "roi") : "organ";
  OrganLook organ_look;  // the source ROI's colour and type, kept by the exported ROI
  // The CT the organ is on: a session's, as its planning model records it (loaded first:
  // the CT a session scene names is checked against it before anything else is done); a
  // planning run's, once read.
  std::optional<CtReference> ct_reference;
  double planning_modelling_s = -1;  // the saved model's own modelling time, for a session
  // A session whose exports need the planning CT, and whose model names none.
  auto no_planning_ct = [&scene] {
    return InputError(scene.path("planning", "model").string() +
                      ": the model has no planning CT to export on");
  };
  if (scene.has_section("planning")) {
    Stopwatch clock;
    const fs::path file = scene.path("planning", "model");
    SavedModel saved = load_model(file);
    if (const std::string w = unchecked_model_warning(file, saved); !w.empty()) warn(w);
    model = std::move(saved.model);
    organ_name = saved.organ_name;
    organ_look = saved.organ_look;
    ct_reference = saved.ct;
    if (ct_reference) check_output_location(out_dir, {ct_reference->folder}, "--out");
    // Exports on the CT's grid need the planning CT: said now, not after the fit.
    const bool exports_on_ct =
        scene.has_section("export") &&
        export_request_from(scene, staging, organ_name, organ_look).needs_ct();
    if (!ct_reference && !scene.has_section("ct") && exports_on_ct) throw no_planning_ct();
    // The planning CT the model records, read by the export stage after the fit (for its
    // files on the CT's grid, or for the report's slices): where it is gone (moved, or
    // another machine), said now.
    std::error_code gone;
    const bool export_reads_ct =
        exports_on_ct || (scene.has_section("export") && scene.has_section("report"));
    if (ct_reference && !scene.has_section("ct") && export_reads_ct &&
        !fs::is_directory(ct_reference->folder, gone))
      throw InputError(fmt::format(
          "{}: the planning CT it records, {}, is not there: give the session scene ct.folder "
          "(where that CT is now)",
          file.string(), ct_reference->folder));
    planning_modelling_s = saved.provenance.value("modelling_wall_s", -1.0);
    model->summary = {
        {"particles", model->state.size()},
        {"radius_mm", model->model->radius_mm()},
        {"skeleton_nodes", model->skeleton ? model->skeleton->skeleton().node_count() : 0},
        {"from_planning_model", file.filename().string()},
        {"planning_scene", saved.provenance.value("scene", "")}};
    record_stage("planning_model", clock.elapsed_s());
    run["model"] = model->summary;
    spdlog::info(
        "planning model: {} particles of {} from {} (built in {:.2f} s by its planning run)",
        model->state.size(), organ_name, file.filename().string(), planning_modelling_s);
  }
  // A phantom is written as DICOM and read back like any planning CT; a CT on a DICOM
  // node is pulled into OUT/cache/ and read likewise. `ct_home`: where the CT's folder is
  // once the run is committed.
  fs::path ct_folder, ct_home, phantom_rtstruct;
  if (scene.has_section("phantom")) {
    Stopwatch clock;
    const fs::path folder = staging / "phantom";
    const SynthResult made = write_pelvis_phantom(folder, phantom_options_from(scene));
    ct_folder = folder / "ct";
    ct_home = out_dir / "phantom" / "ct";
    phantom_rtstruct = folder / "rtstruct.dcm";
    run["phantom"] = {{"kind", scene.text("phantom", "kind")},
                      {"folder", "phantom"},
                      {"true_prostate_volume_cm3", made.prostate_volume_cm3}};
    spdlog::info("phantom: pelvis, {} slices, true prostate {:.2f} cm3, in {}", made.slices,
                 made.prostate_volume_cm3, (out_dir / "phantom").string());
    record_stage("phantom", clock.elapsed_s());
  }
  std::optional<dicom::CtSeries> ct;
  std::optional<dicom::StructureSet> organ_rtstruct;  // the scene's organ.rtstruct, read
  if (scene.has_section("ct") || !ct_folder.empty()) {
    CtStageOptions ct_options = ct_stage_options_from(scene);
    // Of a folder's several series, the one the planning model was built on, or the one the
    // organ's structure set was drawn on (read here for the organ stage; one that cannot be
    // read is left to it to report, after the CT).
    if (ct_reference) {
      ct_options.read.referenced_series_uids = {ct_reference->series_instance_uid};
      ct_options.read.referenced_by = "the planning model";
    }
    if (scene.has_section("organ") && scene.text("organ", "source") == "rtstruct" &&
        scene.is_given("organ", "rtstruct")) {
      try {
        organ_rtstruct = dicom::read_rtstruct(scene.path("organ", "rtstruct"));
        ct_options.read.referenced_series_uids = organ_rtstruct->referenced_series_uids;
      } catch (const InputError&) {
      }
    }
    CtStageResult read = run_ct_stage(ct_options, staging, out_dir, ct_folder, ct_home);
    if (read.pulled) {
      run["ct_pulled"] = read.pulled->summary();
      record_stage("ct_pull", read.pull_wall_s, read.pull_peak_memory_mib);
    }
    ct = std::move(read.ct);
    ct_folder = read.folder;
    ct_home = read.home;
    // A session's CT, when the scene names one, must be the one the model was built on.
    if (scene.has_section("planning") &&
        (!ct_reference || ct->series_instance_uid != ct_reference->series_instance_uid ||
         ct->frame_of_reference_uid != ct_reference->frame_of_reference_uid))
      throw InputError(fmt::format(
          "{}: the planning model was built on another CT series (or Frame of Reference) than "
          "the scene's CT {}",
          scene.path("planning", "model").string(), ct_home.string()));
    record_stage("ct", read.read_wall_s);
    if (!ct->choice.empty()) spdlog::info("ct: {}", ct->choice);
    for (const auto& w : ct->warnings)
      warn(w);
    const auto& g = ct->geometry;
    run["ct"] = {{"slices", g.size[2]},
                 {"size", {g.size[0], g.size[1], g.size[2]}},
                 {"spacing_mm", {g.spacing_mm.x(), g.spacing_mm.y(), g.spacing_mm.z()}}};
    if (!ct->choice.empty()) run["ct"]["series_choice"] = ct->choice;
    spdlog::info("ct: {} x {} x {} voxels of {:.3f} x {:.3f} x {:.3f} mm", g.size[0], g.size[1],
                 g.size[2], g.spacing_mm.x(), g.spacing_mm.y(), g.spacing_mm.z());
  }
  std::optional<geometry::Shape> organ;
  // The organ's structure set: where it is read from, and where it is once the run is
  // committed (the phantom's and a pulled one are in --out).
  fs::path rtstruct_file, organ_structure_set;
  if (scene.has_section("organ") && scene.text("organ", "source") == "rtstruct" &&
      !scene.is_given("organ", "node")) {  // a pulled one: set when pulled
    rtstruct_file =
        scene.is_given("organ", "rtstruct") ? scene.path("organ", "rtstruct") : phantom_rtstruct;
    organ_structure_set =
        scene.is_given("organ", "rtstruct") ? rtstruct_file : out_dir / "phantom" / "rtstruct.dcm";
  }
  if (scene.has_section("organ") && ct) {
    Stopwatch clock;
    OrganStageResult made =
        run_organ_stage(organ_stage_options_from(scene), *ct, rtstruct_file, staging, out_dir,
                        organ_rtstruct ? &*organ_rtstruct : nullptr);
    if (made.pulled) {
      rtstruct_file = made.rtstruct_file;
      organ_structure_set = made.structure_set_home;
      run["organ_pulled"] = made.pulled->summary();
      record_stage("organ_pull", made.pull_wall_s, made.pull_peak_memory_mib);
    }
    for (const auto& w : made.warnings)
      warn(w);
    run["organ"] = made.summary;
    if (scene.text("organ", "source") == "rtstruct") organ_look = made.look;
    organ = std::move(made.shape);
    record_stage("organ", clock.elapsed_s() - made.pull_wall_s);
  }
  // Where the CT and the organ's structure set are (the phantom's: where they will be).
  auto absolute = [](const fs::path& p) { return fs::absolute(p).lexically_normal().string(); };
  if (ct && !scene.has_section("planning"))
    ct_reference =
        CtReference{absolute(ct_home), ct->series_instance_uid, ct->frame_of_reference_uid,
                    organ_structure_set.empty() ? std::string() : absolute(organ_structure_set)};
  // The modelling this run did itself (phantom, CT, organ, model), for the comparison
  // of initial modelling against a session's update.
  auto modelling_s = [&run]() {
    double sum = 0;
    for (const auto& st : run["stages"])
      for (const char* stage_name : {"phantom", "ct", "organ", "model"})
        if (st["name"] == stage_name) sum += st["wall_s"].get<double>();
    return sum;
  };
  if (scene.has_section("model")) {
    Stopwatch clock;
    model = run_model_stage(model_stage_options_from(scene), organ ? &*organ : nullptr);
    record_stage("model", clock.elapsed_s());
    run["model"] = model->summary;
    spdlog::info("model: {} particles, relaxed in {} steps ({:.2f} s), skeleton {:.2f} s",
                 model->state.size(), model->summary["relax_steps"].get<long long>(),
                 model->summary["relax_wall_s"].get<double>(),
                 model->summary["skeleton_wall_s"].get<double>());
    if (!model->summary["relax_settled"].get<bool>()) {
      warn("model: relaxation did not settle within model.relax_steps");
    }
    if (const int pieces = model->summary["components"].get<int>(),
        organ_pieces = model->summary["organ_components"].get<int>();
        pieces > organ_pieces)
      warn(fmt::format(
          "model: the particles make {} separate pieces where the organ is {}: parts of it "
          "thinner than about two particles ({:.1f} mm) hold none (a smaller model.radius_mm "
          "follows them; a grown organ may have leaked along them)",
          pieces, organ_pieces, 2 * model->lattice_spacing_mm));
    if (const int empty = model->summary["organ_parts_without_particles"].get<int>(); empty > 0)
      warn(fmt::format(
          "model: parts of the organ hold no particle: {} of its {} ({:.3f} cm3 in all), smaller "
          "than about one particle ({:.1f} mm); they are exported moved by the deformation "
          "about them, and points on them do not move them (a smaller model.radius_mm fills "
          "them)",
          empty, model->summary["organ_components"].get<int>(),
          model->summary["organ_parts_without_particles_cm3"].get<double>(),
          model->lattice_spacing_mm));
  } else if (!model) {
    spdlog::info("the scene names no model");
  }
  std::optional<PointsStageResult> points;
  std::vector<std::function<void()>>
      deferred_writes;  // files of the stages above, written at the end
  std::vector<std::string> deferred_outputs;
  if (scene.has_section("points") && model) {
    Stopwatch clock;
    if (scene.text("points", "source") == "ultrasound") {
      // The phantom's true anatomy, when there is one, is what the probe images.
      std::optional<geometry::LabelVolume> anatomy;
      if (!phantom_rtstruct.empty())
        anatomy = pelvis_tissue_classes(
            itkbridge::read_label_volume(phantom_rtstruct.parent_path() / "labels.nrrd"));
      UltrasoundStageResult us = run_ultrasound_stage(
          ultrasound_stage_options_from(scene), *model, ct ? &*ct : nullptr,
          organ && organ->mask ? organ->mask.get() : nullptr, anatomy ? &*anatomy : nullptr);
      record_stage("ultrasound", clock.elapsed_s());
      points = std::move(us.points);
      if (points->truth) measure_points_against_truth(*points, us.true_boundary_mm);
      const std::string save = scene.text("ultrasound", "save_volume");
      if (!save.empty() && us.bmode) {
        auto volume = std::make_shared<geometry::LabelVolume>(std::move(*us.bmode));
        deferred_writes.push_back(
            [volume, file = staging / save] { itkbridge::write_label_volume(file, *volume); });
        deferred_outputs.push_back(save);
      }
    } else {
      points = run_points_stage(points_options_from(scene), *model);
      if (!points->truth) check_points_unit(points->points, *model, scene.path("points", "file"));
      for (const auto& w : points->warnings)
        warn(w);
      // Points declared in another CT than the planning CT are in other coordinates.
      if (ct_reference) {
        const PointsCt& declared = points->declared_ct;
        const char* differs =
            !declared.series_instance_uid.empty() &&
                    declared.series_instance_uid != ct_reference->series_instance_uid
                ? "Series Instance UID"
            : !declared.frame_of_reference_uid.empty() &&
                    declared.frame_of_reference_uid != ct_reference->frame_of_reference_uid
                ? "Frame of Reference UID"
                : nullptr;
        if (differs)
          throw InputError(
              fmt::format("{}: its {} is not the planning CT's ({}): the points are "
                          "in another CT's coordinates",
                          scene.path("points", "file").string(), differs, ct_reference->folder));
      }
      record_stage("points", clock.elapsed_s());
    }
    run["points"] = points->summary;
  }
  std::vector<std::pair<std::string, std::string>> files;  // name, content
  std::string not_converged;
  bool deformation_folds = false;                                  // then nothing is exported
  std::shared_ptr<const fitting::Deformation> deformation;         // the fit's, when it ran
  std::shared_ptr<const fitting::SurfaceUncertainty> uncertainty;  // idem
  // The organ the model carries: through the fit's deformation, made once.
  auto organ_of_model = [&] {
    return deformation ? organ_body(*model, deformation) : organ_body(*model);
  };
  std::vector<double> residuals_mm;  // per point, after the fit (for the report)
  if (scene.has_section("fit") && model && points) {
    Stopwatch clock;
    FitStageResult fit;
    try {
      fit = run_fit_stage(fit_stage_options_from(scene), std::move(*model), *points);
    } catch (const particles::StabilityError& e) {
      throw TargetNotMetError(std::string("fit: the simulation could not continue stably: ") +
                              e.what());
    }
    model = std::move(fit.model);
    record_stage("fit", clock.elapsed_s() - fit.truth_wall_s);
    if (fit.truth_wall_s > 0)
      record_stage("truth", fit.truth_wall_s);  // evaluation, not the update
    run["fit"] = fit.fit_summary;
    run["model"]["skin_particles"] = fit.fit_summary["skin_particles"];
    if (!fit.truth_summary.is_null()) run["truth"] = fit.truth_summary;
    files.push_back({"history.csv", fit.history_csv});
    residuals_mm = fit.report.fit.residuals_mm;
    spdlog::info(
        "fit ({}): {} in {} steps, {:.3f} s; residual mean {:.3f} mm, max {:.3f} mm; volume "
        "{:+.2f}%",
        fit.report.method, fit.report.fit.stop_reason, fit.report.fit.steps, fit.report.fit.wall_s,
        fit.report.fit.residual_mean_mm, fit.report.fit.residual_max_mm,
        fit.fit_summary["volume_change_pct"].get<double>());
    // How far the organ went, and where it may be given the points: a fit converges on
    // points of another organ or on points that fix little (one plane, one line), and this
    // is where that shows.
    if (const auto g = fit.fit_summary.find("global"); g != fit.fit_summary.end())
      spdlog::info(
          "fit: the organ moved {:.1f} mm and changed shape by {:.1f} mm (the global stage)",
          (*g)["organ_move_mm"].get<double>(), (*g)["shape_change_mm"].get<double>());
    if (const auto u = fit.fit_summary.find("uncertainty");
        u != fit.fit_summary.end() && u->is_object() && u->contains("all"))
      spdlog::info(
          "fit: uncertainty of the surface (sd) median {:.2f} mm, 95th percentile {:.2f} mm",
          (*u)["all"]["median_mm"].get<double>(), (*u)["all"]["p95_mm"].get<double>());
    if (!fit.truth_summary.is_null()) {
      spdlog::info(
          "truth: mean surface distance {:.3f} mm (undeformed {:.3f}, floor {:.3f}), HD95 {:.3f} "
          "mm, "
          "recovery {:.2f}",
          fit.truth_summary["msd_mm"].get<double>(),
          fit.truth_summary["msd_undeformed_mm"].get<double>(),
          fit.truth_summary["msd_floor_mm"].get<double>(),
          fit.truth_summary["hd95_mm"].get<double>(), fit.truth_summary["recovery"].get<double>());
    }
    for (const auto& w : fit_warnings(fit))
      warn(w);
    not_converged = fit.not_converged_message;
    deformation_folds = fit.deformation_folds;
    deformation = fit.report.deformation;
    uncertainty = fit.report.uncertainty;
    if (!not_converged.empty()) run["warnings"].push_back(not_converged);
  }
  // Export: the (fitted) model on the planning CT's grid (RTSTRUCT, labels), its surface
  // from the particles themselves (a mesh), and the model itself.
  std::optional<PendingExport> pending;
  std::vector<std::string> exported;
  std::string model_file;
  if (scene.has_section("export") && model && !deformation_folds) {
    Stopwatch clock;
    ExportRequest request = export_request_from(scene, staging, organ_name, organ_look);
    request.sigma = uncertainty;
    double ct_read_s = 0;  // its own stage, not the export's
    if ((request.needs_ct() || (scene.has_section("report") && ct_reference)) && !ct) {
      // A session: the planning CT named in the model file, checked to be the same series.
      if (!ct_reference) throw no_planning_ct();
      Stopwatch ct_clock;
      dicom::CtReadOptions o;
      o.series_instance_uid = ct_reference->series_instance_uid;
      ct = dicom::read_ct_series(ct_reference->folder, o);
      if (ct->frame_of_reference_uid != ct_reference->frame_of_reference_uid)
        throw InputError(ct_reference->folder +
                         ": the CT's Frame of Reference is not the planning model's");
      ct_read_s = ct_clock.elapsed_s();
      record_stage("ct", ct_read_s);
    }
    std::optional<dicom::StructureSet> input_rtss;
    if (scene.flag("export", "copy_other_rois")) {
      // The organ's own structure set; a session's, as its model file records it.
      fs::path file;
      if (scene.has_section("planning")) {
        if (!ct_reference || ct_reference->structure_set.empty())
          scene.fail("export", "copy_other_rois",
                     "the planning model records no structure set (its organ was not imported "
                     "from one)");
        file = ct_reference->structure_set;
      } else {
        file = rtstruct_file;
      }
      input_rtss = read_rois_to_copy(file, *ct);
      request.copy_rois_from = &*input_rtss;
      request.skip_roi = organ_name;  // the fitted ROI replaces its source
    }
    if (request.writes_organ()) {  // not for the model file alone (a planning run's)
      pending =
          prepare_export(organ_of_model(), model->model->radius_mm(), ct ? &*ct : nullptr, request);
      for (const auto& w : pending->warnings)
        warn(w);
      for (const auto& f : pending->files)
        exported.push_back(f);
    }
    model_file = scene.text("export", "model");
    if (!model_file.empty()) exported.push_back(model_file);
    record_stage("export", clock.elapsed_s() - ct_read_s);
    spdlog::info("export: {} file(s) prepared", exported.size());
  }
  // Initial modelling against update: what the paper claims is faster.
  {
    nlohmann::json timing = nlohmann::json::object();
    if (!scene.has_section("planning")) timing["modelling_s"] = modelling_s();
    if (planning_modelling_s >= 0) timing["planning_modelling_s"] = planning_modelling_s;
    double update = 0;
    for (const auto& st : run["stages"])
      for (const char* stage_name : {"planning_model", "points", "fit"})
        if (st["name"] == stage_name) update += st["wall_s"].get<double>();
    if (scene.has_section("fit")) timing["update_s"] = update;
    run["timing"] = timing;
    if (planning_modelling_s >= 0 && scene.has_section("fit"))
      spdlog::info(
          "timing: initial modelling {:.2f} s (planning run), update {:.2f} s (this session)",
          planning_modelling_s, update);
  }
  if (!skipped.empty()) {
    std::string list;
    for (const auto& s : skipped)
      list += (list.empty() ? "" : ", ") + s;
    spdlog::info("not built yet in organfit {}: the {} stages; this run did what exists", version(),
                 list);
    run["stages_not_built_yet"] = skipped;
  }

  run["wall_s"] = total.elapsed_s();
  run["peak_memory_mib"] = peak_memory_mib();
  run["outputs"] = {"resolved.yaml", "run.json"};
  if (!phantom_rtstruct.empty()) run["outputs"].push_back("phantom/");
  if (names.count("cache/")) run["outputs"].push_back("cache/");
  for (const auto& f : files)
    run["outputs"].push_back(f.first);
  for (const auto& f : exported)
    run["outputs"].push_back(f);
  for (const auto& f : deferred_outputs)
    run["outputs"].push_back(f);
  run["status"] = not_converged.empty() ? "ok" : "target_not_met";
  // Files are committed only now: a run that fails with an error leaves none. A fit
  // that did not converge still writes its results (run.json says so), then exits 3.
  for (const auto& f : files)
    write_file_atomically(staging / f.first, f.second);
  for (const auto& write : deferred_writes)
    write();
  // The export's files are made and written only now (a failed run leaves none): their
  // time is the export stage's too, with the model file's below.
  auto add_to_stage = [&run](const char* stage_name, double wall_s) {
    for (auto& st : run["stages"])
      if (st["name"] == stage_name) {
        st["wall_s"] = st["wall_s"].get<double>() + wall_s;
        st["peak_memory_mib"] = peak_memory_mib();
      }
  };
  if (pending) {
    Stopwatch clock;
    pending->commit();  // each file atomic; the mesh adds its report
    run["export"] = pending->summary;
    add_to_stage("export", clock.elapsed_s());
  }
  // The planning system gets the objects only from a run that met its target; a failed
  // send leaves them in --out (committed below) and the run exits 2 saying so.
  std::string send_failure;
  if (pending && scene.is_given("export", "send_to")) {
    if (!not_converged.empty()) {
      warn("export: nothing sent to export.send_to: the fit did not converge");
    } else {
      Stopwatch clock;
      std::vector<fs::path> dicom_files;
      for (const char* key : {"rtstruct", "registration"})
        if (!scene.text("export", key).empty())
          dicom_files.push_back(staging / scene.text("export", key));
      try {
        run["export"]["sent"] = send_exported(send_options_from(scene), dicom_files);
        spdlog::info("export: {} object(s) sent to {} in {:.2f} s", dicom_files.size(),
                     scene.text("export", "send_to"), clock.elapsed_s());
      } catch (const Error& e) {
        send_failure = e.what();
        run["export"]["send_failed"] = send_failure;
        run["warnings"].push_back(send_failure);
        run["status"] = "send_failed";
      }
      record_stage("send", clock.elapsed_s());
    }
  }
  if (!model_file.empty()) {
    const nlohmann::json provenance = {
        {"organfit_version", version()},
        {"scene", name},
        {"modelling_wall_s", planning_modelling_s >= 0 ? planning_modelling_s : modelling_s()},
        {"fitted", scene.has_section("fit")}};
    Stopwatch clock;
    save_model(staging / model_file, *model, organ_name, organ_look, ct_reference, provenance,
               uncertainty.get());
    add_to_stage("export", clock.elapsed_s());
  }
  if (scene.has_section("report")) {
    Stopwatch clock;
    ReportContext context;
    context.scene_yaml = scene.resolved_yaml();
    for (const auto& f : files)
      if (f.first == "history.csv") context.history_csv = f.second;
    context.ct = ct ? &*ct : nullptr;
    context.planning = model ? &model->shape : nullptr;
    std::optional<fitting::EmbeddedBody> fitted_organ;
    if (model) fitted_organ.emplace(organ_of_model());
    context.fitted = fitted_organ ? &*fitted_organ : nullptr;
    context.rho_mm = model ? model->model->radius_mm() : 0;
    if (pending) {  // the organ the export made, not made a second time
      context.fitted_on_ct = pending->organ_on_ct.get();
      context.fitted_on_mesh_grid = pending->organ_on_mesh_grid.get();
    }
    if (points)
      for (const auto& p : points->points)
        context.points_mm.push_back(p.p_mm);
    context.residuals_mm = residuals_mm;
    context.uncertainty = uncertainty.get();
    context.show_patient = scene.flag("report", "show_patient") && run_options.show_phi;
    if (scene.flag("report", "show_patient") && !run_options.show_phi)
      warn(
          "report: the patient's name and ID are not shown: report.show_patient needs --show-phi "
          "on the command line");
    const std::string file = scene.text("report", "file");
    run["outputs"].push_back(file);
    record_stage("report", clock.elapsed_s());  // the page's own time is shown without itself
    context.run = run;
    write_file_atomically(staging / file, build_report(context));
    run["stages"].back()["wall_s"] = clock.elapsed_s();
    run["stages"].back()["peak_memory_mib"] = peak_memory_mib();
    spdlog::info("report: {}", (out_dir / file).string());
  }
  // The whole run's, the report included (the page shows them as they were before it).
  run["wall_s"] = total.elapsed_s();
  run["peak_memory_mib"] = peak_memory_mib();
  write_file_atomically(staging / "resolved.yaml", scene.resolved_yaml());
  write_file_atomically(staging / "run.json", run.dump(2) + "\n");
  output.commit();
  if (!send_failure.empty())
    throw dicomnet::NodeError(send_failure + "; the written files are in " + out_dir.string());
  if (!not_converged.empty()) throw TargetNotMetError(not_converged);
  return run;
}

}  // namespace

nlohmann::json run_scene(const config::Scene& scene, const fs::path& out_dir,
                         const RunOptions& run_options) {
  std::error_code ec;
  if (fs::exists(out_dir, ec) && !fs::is_directory(out_dir, ec))
    throw InputError(out_dir.string() + ": --out exists and is not a folder");
  check_output_location(out_dir, scene_inputs(scene), "--out");
  const std::set<std::string> names = names_written(scene);
  OutputFolder output(out_dir, names);
  // An error names a file where the user will look for it, not in the staging folder it
  // was being written in.
  try {
    return run_into(scene, out_dir, run_options, names, output);
  } catch (const Error& e) {
    throw Error(e.code(), output.in_final_names(e.what()));
  }
}

}  // namespace organfit::pipeline
