#include "organfit/pipeline/runner.h"

#include <fmt/format.h>
#include <omp.h>
#include <spdlog/spdlog.h>

#include <functional>
#include <optional>
#include <set>

#include "organfit/dicom/rtstruct_writer.h"
#include "organfit/dicom/structure_set.h"
#include "organfit/geometry/mask_ops.h"
#include "organfit/geometry/slice_contours.h"
#include "organfit/itkbridge/itk_images.h"
#include "organfit/meshing/surface.h"
#include "organfit/pipeline/export_stage.h"
#include "organfit/pipeline/fit_stage.h"
#include "organfit/pipeline/model_file.h"
#include "organfit/pipeline/model_stage.h"
#include "organfit/pipeline/node_stage.h"
#include "organfit/pipeline/report_stage.h"
#include "organfit/pipeline/synth_command.h"
#include "organfit/pipeline/ultrasound_stage.h"
#include "organfit/segmentation/segment.h"
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
  std::set<std::string> names = {"run.json", "resolved.yaml"};
  if (scene.has_section("phantom")) names.insert("phantom/");
  if ((scene.has_section("ct") && scene.is_given("ct", "node")) ||
      (scene.has_section("organ") && scene.is_given("organ", "node")))
    names.insert("cache/");
  if (scene.has_section("fit")) names.insert("history.csv");
  if (scene.has_section("export"))
    for (const char* key : {"rtstruct", "labels", "mesh", "model", "displacement_field",
                            "registration", "jacobian", "uncertainty"})
      if (!scene.text("export", key).empty()) names.insert(scene.text("export", key));
  if (scene.has_section("ultrasound") && !scene.text("ultrasound", "save_volume").empty())
    names.insert(scene.text("ultrasound", "save_volume"));
  if (scene.has_section("report")) names.insert(scene.text("report", "file"));
  return names;
}

}  // namespace

nlohmann::json run_scene(const config::Scene& scene, const fs::path& out_dir,
                         const RunOptions& run_options) {
  std::error_code ec;
  if (fs::exists(out_dir, ec) && !fs::is_directory(out_dir, ec))
    throw InputError(out_dir.string() + ": --out exists and is not a folder");
  check_output_location(out_dir, scene_inputs(scene), "--out");
  // Everything is written under the staging folder and moved into --out at the end.
  const std::set<std::string> names = names_written(scene);
  OutputFolder output(out_dir, names);
  const fs::path& stage = output.staging();
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
  auto record_stage = [&](const char* stage, double wall_s) {
    run["stages"].push_back(
        {{"name", stage}, {"wall_s", wall_s}, {"peak_memory_mib", peak_memory_mib()}});
  };

  std::vector<std::string> skipped;
  for (const auto& stage : pipeline_stages()) {
    if (!stage.available) skipped.push_back(stage.name);
  }

  auto warn = [&](const std::string& w) {
    spdlog::warn(w);
    run["warnings"].push_back(w);
  };
  std::optional<ModelStageResult> model;
  std::string organ_name = scene.has_section("organ") ? scene.text("organ", "roi") : "organ";
  OrganLook organ_look;  // the source ROI's colour and type, kept by the exported ROI
  std::optional<CtReference> ct_reference;
  // A session starts from its planning model (loaded first: the CT a session scene names
  // is checked against it before anything else is done).
  std::optional<CtReference> planning_ct;
  double planning_modelling_s = -1;  // the saved model's own modelling time, for a session
  if (scene.has_section("planning")) {
    Stopwatch clock;
    const fs::path file = scene.path("planning", "model");
    SavedModel saved = load_model(file);
    model = std::move(saved.model);
    organ_name = saved.organ_name;
    organ_look = saved.organ_look;
    ct_reference = saved.ct;
    planning_ct = saved.ct;
    if (ct_reference) check_output_location(out_dir, {ct_reference->folder}, "--out");
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
    phantom::PelvisOptions p;
    p.seed = static_cast<std::uint64_t>(scene.integer("phantom", "seed"));
    p.columns = static_cast<int>(scene.integer("phantom", "columns"));
    p.rows = static_cast<int>(scene.integer("phantom", "rows"));
    p.slices = static_cast<int>(scene.integer("phantom", "slices"));
    p.pixel_mm = scene.number("phantom", "pixel_mm");
    p.slice_mm = scene.number("phantom", "slice_mm");
    p.noise_hu = scene.number("phantom", "noise_hu");
    const fs::path folder = stage / "phantom";
    const SynthResult made = run_synth_pelvis(folder, p);
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
  if (scene.has_section("ct") || !ct_folder.empty()) {
    Stopwatch clock;
    dicom::CtReadOptions o;
    if (scene.has_section("ct")) {
      o.series_instance_uid = scene.text("ct", "series_uid");
      o.series_description = scene.text("ct", "series_description");
      if (scene.is_given("ct", "node")) {
        ct_folder = stage / "cache" / "ct";
        ct_home = out_dir / "cache" / "ct";
        const PulledSeries pulled = pull_ct(scene, ct_folder);
        o.series_instance_uid = pulled.series_uid;
        run["ct_pulled"] = pulled.summary();
        record_stage("ct_pull", clock.elapsed_s());
        spdlog::info("ct: {} objects pulled from {} in {:.2f} s (C-FIND {:.2f} s, C-GET {:.2f} s)",
                     pulled.files.size(), scene.text("ct", "node"), clock.elapsed_s(),
                     pulled.find_s, pulled.get_s);
        clock.restart();
      } else {
        ct_folder = scene.path("ct", "folder");
        ct_home = ct_folder;
      }
    }
    ct = dicom::read_ct_series(ct_folder, o);
    // A session's CT, when the scene names one, must be the one the model was built on.
    if (scene.has_section("planning") &&
        (!planning_ct || ct->series_instance_uid != planning_ct->series_instance_uid ||
         ct->frame_of_reference_uid != planning_ct->frame_of_reference_uid))
      throw InputError(fmt::format(
          "{}: the planning model was built on another CT series (or Frame of Reference) than "
          "the scene's CT {}",
          scene.path("planning", "model").string(), ct_home.string()));
    record_stage("ct", clock.elapsed_s());
    for (const auto& w : ct->warnings)
      warn(w);
    const auto& g = ct->geometry;
    run["ct"] = {{"slices", g.size[2]},
                 {"size", {g.size[0], g.size[1], g.size[2]}},
                 {"spacing_mm", {g.spacing_mm.x(), g.spacing_mm.y(), g.spacing_mm.z()}}};
    spdlog::info("ct: {} x {} x {} voxels of {:.3f} x {:.3f} x {:.3f} mm", g.size[0], g.size[1],
                 g.size[2], g.spacing_mm.x(), g.spacing_mm.y(), g.spacing_mm.z());
  }
  std::optional<evaluation::Shape> organ;
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
    const std::string roi = scene.text("organ", "roi");
    geometry::LabelVolume mask;
    if (scene.text("organ", "source") == "seed") {
      segmentation::SeedOptions s;
      s.seed_mm = scene.vec3("organ", "seed_mm");
      s.hu_low = scene.number("organ", "hu_low");
      s.hu_high = scene.number("organ", "hu_high");
      s.smoothing_iterations = static_cast<int>(scene.integer("organ", "smoothing_iterations"));
      s.opening_radius_voxels = static_cast<int>(scene.integer("organ", "opening_radius_voxels"));
      s.search_box_mm = scene.number("organ", "search_box_mm");
      segmentation::SeededOrgan grown = segmentation::segment_from_seed(ct->geometry, ct->hu, s);
      for (const auto& w : grown.warnings)
        warn(w);
      mask = std::move(grown.mask);
      run["organ"] = {
          {"roi", roi}, {"source", "seed"}, {"volume_cm3", mask.volume_mm3(1) / 1000.0}};
      spdlog::info("organ: '{}' grown from the seed, {:.2f} cm3", roi, mask.volume_mm3(1) / 1000.0);
    } else {
      if (scene.is_given("organ", "node")) {
        const PulledSeries pulled =
            pull_structure_set(scene, ct->patient.study_instance_uid, stage / "cache" / "rtstruct");
        rtstruct_file = pulled.files.front();
        organ_structure_set = out_dir / fs::relative(rtstruct_file, stage);
        run["organ_pulled"] = pulled.summary();
        record_stage("organ_pull", clock.elapsed_s());
        spdlog::info("organ: the structure set pulled from {} in {:.2f} s",
                     scene.text("organ", "node"), clock.elapsed_s());
        clock.restart();
      }
      const fs::path& file = rtstruct_file;
      dicom::RasterisedRoi r =
          dicom::rasterise_roi(dicom::read_rtstruct(file), roi, *ct, file.string(),
                               static_cast<int>(scene.integer("organ", "roi_number")));
      for (const auto& w : r.warnings)
        warn(w);
      run["organ"] = {{"roi", roi},
                      {"source", "rtstruct"},
                      {"contours", r.contours},
                      {"matched_by_position", r.matched_by_position},
                      {"volume_cm3", r.mask.volume_mm3(1) / 1000.0}};
      spdlog::info("organ: ROI '{}', {} contours, {:.2f} cm3", roi, r.contours,
                   r.mask.volume_mm3(1) / 1000.0);
      organ_look = {r.colour, r.interpreted_type};  // an empty type is written as ORGAN
      mask = std::move(r.mask);
    }
    if (mask.count(1) == 0)
      scene.fail("organ", "roi", "the organ '" + echo(roi) + "' covers no voxel of the CT");
    organ =
        evaluation::make_mask_shape(std::make_shared<const geometry::LabelVolume>(std::move(mask)));
    record_stage("organ", clock.elapsed_s());
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
      for (const char* stage : {"phantom", "ct", "organ", "model"})
        if (st["name"] == stage) sum += st["wall_s"].get<double>();
    return sum;
  };
  if (scene.has_section("model")) {
    Stopwatch clock;
    model = run_model_stage(scene, organ ? &*organ : nullptr);
    record_stage("model", clock.elapsed_s());
    run["model"] = model->summary;
    spdlog::info("model: {} particles, relaxed in {} steps ({:.2f} s), skeleton {:.2f} s",
                 model->state.size(), model->summary["relax_steps"].get<long long>(),
                 model->summary["relax_wall_s"].get<double>(),
                 model->summary["skeleton_wall_s"].get<double>());
    if (!model->summary["relax_settled"].get<bool>()) {
      warn("model: relaxation did not settle within model.relax_steps");
    }
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
          scene, *model, ct ? &*ct : nullptr, organ && organ->mask ? organ->mask.get() : nullptr,
          anatomy ? &*anatomy : nullptr);
      record_stage("ultrasound", clock.elapsed_s());
      points = std::move(us.points);
      if (points->truth) {
        // How far the extracted points lie from the true (deformed) surface: against a
        // dense noise-free sampling of it (0.2 mm apart on a 35 cm3 organ).
        evaluation::SamplingOptions dense;
        dense.count = 40000;
        dense.noise_mm = 0;
        const auto surface =
            evaluation::sample_deformed_surface(points->truth_shape, *points->truth, dense);
        std::vector<double> d;
        for (const auto& p : points->points) {
          double best = 1e300;
          for (const auto& q : surface)
            best = std::min(best, (p.p_mm - q.p_mm).squaredNorm());
          d.push_back(std::sqrt(best));
          if (d.back() > 1.5)
            spdlog::debug(
                "ultrasound: point ({:.1f}, {:.1f}, {:.1f}) mm, confidence {:.2f}, is {:.2f} mm "
                "off",
                p.p_mm.x(), p.p_mm.y(), p.p_mm.z(), p.confidence, d.back());
        }
        std::sort(d.begin(), d.end());
        const double within =
            static_cast<double>(std::upper_bound(d.begin(), d.end(), 1.5) - d.begin()) / d.size();
        points->summary["median_distance_to_true_surface_mm"] = d[d.size() / 2];
        points->summary["fraction_within_1_5_mm"] = within;
        points->summary["distance_to_true_surface_p90_mm"] = d[d.size() * 9 / 10];
        points->summary["distance_to_true_surface_max_mm"] = d.back();
        // ... and whether they lie on the part of it the probe sees (within 1.5 mm of
        // where the simulator's rays crossed the organ's boundary before any shadow).
        int on_visible = 0;
        for (const auto& p : points->points) {
          double best = 1e300;
          for (const auto& q : us.true_boundary_mm)
            best = std::min(best, (p.p_mm - q).squaredNorm());
          on_visible += best <= 1.5 * 1.5;
        }
        points->summary["fraction_on_visible_surface"] =
            static_cast<double>(on_visible) / points->points.size();
        spdlog::info(
            "ultrasound: points lie {:.2f} mm (median) from the true surface; {:.0f}% within 1.5 "
            "mm",
            d[d.size() / 2], 100 * within);
      }
      const std::string save = scene.text("ultrasound", "save_volume");
      if (!save.empty() && us.bmode) {
        auto volume = std::make_shared<geometry::LabelVolume>(std::move(*us.bmode));
        deferred_writes.push_back(
            [volume, file = stage / save] { itkbridge::write_label_volume(file, *volume); });
        deferred_outputs.push_back(save);
      }
    } else {
      points = run_points_stage(scene, *model);
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
      fit = run_fit_stage(scene, *model, *points);
    } catch (const particles::StabilityError& e) {
      throw TargetNotMetError(std::string("fit: the simulation could not continue stably: ") +
                              e.what());
    }
    record_stage("fit", clock.elapsed_s() - fit.truth_wall_s);
    if (fit.truth_wall_s > 0)
      record_stage("truth", fit.truth_wall_s);  // evaluation, not the update
    run["fit"] = fit.fit_summary;
    run["model"]["skin_particles"] = fit.fit_summary["skin_particles"];
    if (!fit.truth_summary.is_null()) run["truth"] = fit.truth_summary;
    files.push_back({"history.csv", fit.history_csv});
    residuals_mm = fit.fit.residuals_mm;
    spdlog::info(
        "fit ({}): {} in {} steps, {:.3f} s; residual mean {:.3f} mm, max {:.3f} mm; volume "
        "{:+.2f}%",
        fit.fit_summary["method"].get<std::string>(), fit.fit.stop_reason, fit.fit.steps,
        fit.fit.wall_s, fit.fit.residual_mean_mm, fit.fit.residual_max_mm,
        fit.fit_summary["volume_change_pct"].get<double>());
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
    const double organ_change = fit.fit_summary["volume_change_pct"].get<double>();
    const double balls_change = fit.fit_summary["particle_body_volume_change_pct"].get<double>();
    if (std::abs(organ_change) > 1.0)
      warn(
          std::abs(balls_change) <= 1.0 && std::abs(organ_change) > 3.0
              ? fmt::format(
                    "fit: the organ's volume changed by {:+.1f}% while the particles' own body "
                    "changed by {:+.1f}%: the particles rearranged under a deformation larger than "
                    "the global map explains, and the organ they carry is not to be trusted there",
                    organ_change, balls_change)
              : fmt::format("fit: the organ's volume changed by {:+.1f}%", organ_change));
    if (fit.global_map.shears_dropped)
      warn(
          "fit: the points asked for an implausible bend (fit.max_global_stretch and a quarter of "
          "the organ's size bound it); the global stage used a stretch and shift only");
    if (fit.fit_summary["rejected_points"].get<int>() > 0) {
      warn(fmt::format("fit: {} points rejected as outliers",
                       fit.fit_summary["rejected_points"].get<int>()));
    }
    not_converged = fit.not_converged_message;
    deformation_folds = fit.deformation_folds;
    deformation = fit.deformation;
    uncertainty = fit.uncertainty;
    if (!not_converged.empty()) run["warnings"].push_back(not_converged);
  }
  // Export: the (fitted) model on the planning CT's grid (RTSTRUCT, labels), its surface
  // from the particles themselves (a mesh), and the model itself.
  std::optional<PendingExport> pending;
  std::vector<std::string> exported;
  std::string model_file;
  if (scene.has_section("export") && model && !deformation_folds) {
    Stopwatch clock;
    ExportRequest request;
    auto in_out = [&](const char* key) {
      const std::string& file = scene.text("export", key);
      return file.empty() ? fs::path() : stage / file;
    };
    request.rtstruct = in_out("rtstruct");
    request.labels = in_out("labels");
    request.mesh = in_out("mesh");
    request.displacement_field = in_out("displacement_field");
    request.jacobian = in_out("jacobian");
    request.uncertainty = in_out("uncertainty");
    request.sigma = uncertainty;
    request.registration = in_out("registration");
    request.field_spacing_mm = scene.number("export", "field_spacing_mm");
    request.roi_name = scene.text("export", "roi_name");
    request.fixed_uids = scene.flag("export", "fixed_uids");
    if (request.roi_name.empty()) request.roi_name = organ_name + "_fit";
    request.roi_colour = organ_look.colour;
    request.roi_type = organ_look.interpreted_type;
    if (const Eigen::Vector3d c = scene.vec3("export", "roi_color");
        c != Eigen::Vector3d(-1, -1, -1)) {
      for (int i = 0; i < 3; ++i)
        request.roi_colour[static_cast<size_t>(i)] = static_cast<int>(std::lround(c[i]));
    }
    double ct_read_s = 0;  // its own stage, not the export's
    if ((request.needs_ct() || (scene.has_section("report") && ct_reference)) && !ct) {
      // A session: the planning CT named in the model file, checked to be the same series.
      if (!ct_reference)
        throw InputError(scene.path("planning", "model").string() +
                         ": the model has no planning CT to export on");
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
    pending =
        prepare_export(organ_of_model(), model->model->radius_mm(), ct ? &*ct : nullptr, request);
    for (const auto& w : pending->warnings)
      warn(w);
    for (const auto& f : pending->files)
      exported.push_back(f);
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
      for (const char* stage : {"planning_model", "points", "fit"})
        if (st["name"] == stage) update += st["wall_s"].get<double>();
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
    write_file_atomically(stage / f.first, f.second);
  for (const auto& write : deferred_writes)
    write();
  if (pending) {
    pending->commit();  // each file atomic; the mesh adds its report
    run["export"] = pending->summary;
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
          dicom_files.push_back(stage / scene.text("export", key));
      try {
        run["export"]["sent"] = send_exported(scene, dicom_files);
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
    save_model(stage / model_file, *model, organ_name, organ_look, ct_reference, provenance);
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
    write_file_atomically(stage / file, build_report(context));
    run["stages"].back()["wall_s"] = clock.elapsed_s();
    run["stages"].back()["peak_memory_mib"] = peak_memory_mib();
    spdlog::info("report: {}", (out_dir / file).string());
  }
  // The whole run's, the report included (the page shows them as they were before it).
  run["wall_s"] = total.elapsed_s();
  run["peak_memory_mib"] = peak_memory_mib();
  write_file_atomically(stage / "resolved.yaml", scene.resolved_yaml());
  write_file_atomically(stage / "run.json", run.dump(2) + "\n");
  output.commit();
  if (!send_failure.empty())
    throw dicomnet::NodeError(send_failure + "; the written files are in " + out_dir.string());
  if (!not_converged.empty()) throw TargetNotMetError(not_converged);
  return run;
}

}  // namespace organfit::pipeline
