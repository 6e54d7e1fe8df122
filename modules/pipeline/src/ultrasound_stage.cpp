#include "organfit/pipeline/ultrasound_stage.h"

#include <fmt/format.h>
#include <spdlog/spdlog.h>

#include <Eigen/Geometry>
#include <Eigen/LU>
#include <cmath>
#include <optional>

#include "organfit/dicom/us_image.h"
#include "organfit/itkbridge/itk_images.h"
#include "organfit/phantom/pelvis.h"
#include "organfit/pipeline/scene_schema.h"
#include "organfit/support/error.h"
#include "organfit/support/resources.h"
#include "organfit/ultrasound/boundary_points.h"
#include "organfit/ultrasound/sequence_metafile.h"
#include "organfit/ultrasound/simulator.h"

namespace organfit::pipeline {

geometry::LabelVolume tissue_classes(const geometry::ImageGeometry& g, const std::vector<float>& hu,
                                     const geometry::LabelVolume* organ) {
  geometry::LabelVolume t(g);
  for (size_t v = 0; v < hu.size(); ++v) {
    const float h = hu[v];
    t.labels[v] = h < -400 ? 1 : h < -30 ? 2 : h < 25 ? 3 : h < 150 ? 4 : h < 400 ? 5 : 6;
    if (organ && organ->labels[v] == 1) t.labels[v] = 7;
  }
  return t;
}

geometry::LabelVolume pelvis_tissue_classes(const geometry::LabelVolume& labels) {
  geometry::LabelVolume t(labels.geometry);
  for (size_t v = 0; v < labels.labels.size(); ++v) {
    switch (labels.labels[v]) {
      case phantom::kAir:
        t.labels[v] = 1;
        break;
      case phantom::kSoftTissue:
        t.labels[v] = 2;
        break;  // fat
      case phantom::kBladder:
        t.labels[v] = 3;
        break;  // urine
      case phantom::kMuscle:
      case phantom::kRectum:
        t.labels[v] = 4;
        break;  // rectal gas: shadow from HU
      case phantom::kProstate:
        t.labels[v] = 7;
        break;
      default:
        t.labels[v] = 6;  // bone
    }
  }
  return t;
}

ultrasound::TissueAt deformed_anatomy(const geometry::LabelVolume& tissue,
                                      const std::vector<float>& hu, const geometry::Shape& organ,
                                      const evaluation::Deformation& d) {
  // The organ by its smooth shape pulled back through the map, everything else where the
  // planning CT has it, fat where the organ was and is no more. Deforming the whole
  // pelvis instead would also stretch the rectal gas round the probe and shadow half the
  // field. Copies are captured: the simulator calls this from several threads.
  return [tissue = std::make_shared<const geometry::LabelVolume>(tissue),
          hu = std::make_shared<const std::vector<float>>(hu), organ, d](const Eigen::Vector3d& p) {
    if (organ.inside(d.inverse(p))) return ultrasound::TissueSample{7, 40.0f};
    const auto& g = tissue->geometry;
    const Eigen::Vector3d idx = g.physical_to_index(p);
    const int i = static_cast<int>(std::lround(idx.x())),
              j = static_cast<int>(std::lround(idx.y())),
              k = static_cast<int>(std::lround(idx.z()));
    if (i < 0 || j < 0 || k < 0 || i >= g.size[0] || j >= g.size[1] || k >= g.size[2])
      return ultrasound::TissueSample{};
    const auto v = static_cast<size_t>(g.linear_index(i, j, k));
    if (tissue->labels[v] == 7) return ultrasound::TissueSample{2, -95.0f};  // vacated: fat
    return ultrasound::TissueSample{tissue->labels[v], (*hu)[v]};
  };
}

UltrasoundStageOptions ultrasound_stage_options_from(const config::Scene& scene) {
  UltrasoundStageOptions o;
  o.source = scene.text("ultrasound", "source");
  o.registration = scene.matrix4("ultrasound", "registration");
  o.source_key = scene.key("ultrasound", "source");
  o.probe_axis_key = scene.key("ultrasound", "probe_axis");
  if (o.source == "simulate") {
    o.deformation = true_deformation_from(scene);
    o.probe_offset_mm = scene.vec3("ultrasound", "probe_offset_mm");
    o.probe_axis = scene.vec3("ultrasound", "probe_axis").normalized();
    o.probe_lateral = scene.vec3("ultrasound", "probe_lateral").normalized();
    o.simulator = keys::ultrasound_simulator().read(scene, tissue_class_simulator_options());
    o.simulator.lateral_half_angle_deg = o.simulator.elevation_half_angle_deg =
        scene.number("ultrasound", "half_angle_deg");
    o.simulator.seed = static_cast<std::uint64_t>(scene.integer("scene", "seed"));
  } else if (o.source == "volume") {
    o.file = scene.path("ultrasound", "file");
  } else {
    o.calibration = scene.matrix4("ultrasound", "calibration");
    o.file = scene.path("ultrasound", "file");
    if (o.source == "sweep") {
      if (scene.is_given("ultrasound", "tracker")) o.tracker = scene.path("ultrasound", "tracker");
      o.transform = scene.text("ultrasound", "transform");
    } else {
      o.pixel_mm = scene.number("ultrasound", "pixel_mm");
    }
  }
  o.boundary = keys::ultrasound_boundary().read(scene);
  o.boundary.target_count = static_cast<int>(scene.integer("points", "count"));
  return o;
}

UltrasoundStageResult run_ultrasound_stage(const UltrasoundStageOptions& options,
                                           const ModelStageResult& model, const dicom::CtSeries* ct,
                                           const geometry::LabelVolume* organ_mask,
                                           const geometry::LabelVolume* anatomy) {
  UltrasoundStageResult r;
  PointsStageResult& pts = r.points;
  const Eigen::Matrix4d& registration = options.registration;
  ultrasound::TrackedSweep sweep;  // 2D sources
  geometry::ImageGeometry us_geometry;
  std::vector<float> intensity;
  std::vector<std::uint8_t> in_view;
  nlohmann::json summary;
  const std::string& source = options.source;
  if (source == "simulate") {
    if (!ct || !organ_mask)
      options.source_key.fail(
          "simulating ultrasound needs the planning CT and the organ (ct/phantom, organ)");
    Stopwatch clock;
    const evaluation::Deformation d = deformation_about(options.deformation, model.shape);
    const geometry::LabelVolume tissue =
        anatomy ? *anatomy : tissue_classes(ct->geometry, ct->hu, organ_mask);
    const ultrasound::TissueAt today = deformed_anatomy(tissue, ct->hu, model.shape, d);
    ultrasound::ProbePose probe;
    probe.position_mm = model.shape.centre_mm + options.probe_offset_mm;
    probe.axis = options.probe_axis;
    probe.lateral = options.probe_lateral;
    const ultrasound::SimulatorOptions& so = options.simulator;
    ultrasound::SimulatedUltrasound sim;
    try {
      sim = ultrasound::simulate_bmode(today, probe, so);
    } catch (const std::invalid_argument& e) {
      options.probe_axis_key.fail(e.what());
    }
    us_geometry = sim.geometry;
    intensity.assign(sim.bmode.begin(), sim.bmode.end());
    in_view = sim.in_view;
    r.true_boundary_mm = sim.true_boundary_mm;
    pts.truth = d;
    pts.truth_shape = model.shape;
    geometry::LabelVolume bmode(sim.geometry);
    bmode.labels = sim.bmode;
    r.bmode = std::move(bmode);
    summary = {{"source", "simulate"},
               {"probe_mm", {probe.position_mm.x(), probe.position_mm.y(), probe.position_mm.z()}},
               {"speckle", so.speckle},
               {"volume_size", {us_geometry.size[0], us_geometry.size[1], us_geometry.size[2]}},
               {"visible_boundary_samples", sim.true_boundary_mm.size()},
               {"stretch", d.stretch},
               {"bend_mm", d.bend_mm},
               {"simulate_wall_s", clock.elapsed_s()}};
  } else if (source == "volume") {
    const auto image = itkbridge::read_scalar_image(options.file);
    us_geometry = image.geometry;
    intensity = image.values;
    summary = {{"source", "volume"},
               {"volume_size", {us_geometry.size[0], us_geometry.size[1], us_geometry.size[2]}}};
  } else {
    // 2D frames: a tracked sweep, or DICOM frames placed by the calibration alone.
    const Eigen::Matrix4d& calibration = options.calibration;
    if (source == "sweep") {
      const auto video = ultrasound::read_sequence_metafile(options.file);
      std::optional<ultrasound::SequenceMetafile> tracker;
      if (options.tracker) tracker = ultrasound::read_sequence_metafile(*options.tracker, false);
      ultrasound::SweepOptions so;
      so.transform = options.transform;
      so.image_to_probe = calibration;
      so.tracker_to_ct = registration;
      sweep = ultrasound::assemble_sweep(video, tracker ? &*tracker : nullptr, so);
      summary = {{"source", "sweep"},
                 {"frames", video.frames.size()},
                 {"frames_used", sweep.frames.size()}};
    } else {
      const dicom::UsImage us = dicom::read_us_image(options.file, options.pixel_mm);
      Eigen::Matrix4d scale = Eigen::Matrix4d::Identity();
      scale(0, 0) = us.pixel_mm_x, scale(1, 1) = us.pixel_mm_y;
      const size_t n = static_cast<size_t>(us.width) * us.height;
      for (int f = 0; f < us.frames; ++f) {
        ultrasound::TrackedFrame frame;
        frame.index = f, frame.width = us.width, frame.height = us.height;
        frame.pixels.assign(us.grey.begin() + static_cast<long>(f * n),
                            us.grey.begin() + static_cast<long>((f + 1) * n));
        frame.pixel_to_ct_mm = registration * calibration * scale;
        sweep.frames.push_back(std::move(frame));
      }
      summary = {
          {"source", "dicom"}, {"frames", us.frames}, {"pixel_mm", {us.pixel_mm_x, us.pixel_mm_y}}};
    }
  }
  Stopwatch clock;
  ultrasound::BoundaryOptions bo = options.boundary;
  bo.centre_mm = model.shape.centre_mm;
  bo.r_max_mm = 0.5 * model.shape.size_mm.maxCoeff() + bo.band_mm;
  const geometry::Shape& prior = model.shape;
  bo.prior_inside = [&prior](const Eigen::Vector3d& p) { return prior.inside(p); };
  ultrasound::BoundaryResult found;
  try {
    if (!sweep.frames.empty()) {
      found = ultrasound::sweep_boundary_points(sweep, bo);  // already in CT coordinates
    } else {
      // A volume is searched in its own frame: the organ and its prior mapped into it.
      const Eigen::Matrix4d to_volume = source == "volume" ? Eigen::Matrix4d(registration.inverse())
                                                           : Eigen::Matrix4d::Identity();
      bo.centre_mm = (to_volume * model.shape.centre_mm.homogeneous()).head<3>();
      const Eigen::Matrix4d to_ct = to_volume.inverse();
      bo.prior_inside = [&prior, to_ct](const Eigen::Vector3d& p) {
        return prior.inside((to_ct * p.homogeneous()).head<3>());
      };
      found = ultrasound::boundary_points(us_geometry, intensity,
                                          in_view.empty() ? nullptr : &in_view, bo);
      for (auto& p : found.points)
        p.p_mm = (to_ct * p.p_mm.homogeneous()).head<3>();
    }
  } catch (const std::invalid_argument& e) {
    throw InputError(std::string("ultrasound: ") + e.what());
  }
  if (found.points.empty())
    throw TargetNotMetError(
        "ultrasound: no boundary points found (the organ may be outside the field of view)");
  for (const auto& p : found.points)
    pts.points.push_back({p.p_mm, p.confidence});
  summary["rays"] = found.rays;
  summary["rays_with_a_boundary"] = found.rays_in_view;
  summary["rejected_by_neighbours"] = found.rejected;
  summary["count"] = pts.points.size();
  summary["segment_wall_s"] = clock.elapsed_s();
  pts.summary = summary;
  spdlog::info("ultrasound: {} points from {} rays with a boundary ({} rejected as inconsistent)",
               pts.points.size(), found.rays_in_view, found.rejected);
  return r;
}

void measure_points_against_truth(PointsStageResult& points,
                                  const std::vector<Eigen::Vector3d>& true_boundary_mm) {
  // How far the extracted points lie from the true (deformed) surface: against a
  // dense noise-free sampling of it (0.2 mm apart on a 35 cm3 organ).
  evaluation::SamplingOptions dense;
  dense.count = 40000;
  dense.noise_mm = 0;
  const auto surface =
      evaluation::sample_deformed_surface(points.truth_shape, *points.truth, dense);
  std::vector<double> d;
  for (const auto& p : points.points) {
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
  points.summary["median_distance_to_true_surface_mm"] = d[d.size() / 2];
  points.summary["fraction_within_1_5_mm"] = within;
  points.summary["distance_to_true_surface_p90_mm"] = d[d.size() * 9 / 10];
  points.summary["distance_to_true_surface_max_mm"] = d.back();
  // ... and whether they lie on the part of it the probe sees (within 1.5 mm of
  // where the simulator's rays crossed the organ's boundary before any shadow).
  int on_visible = 0;
  for (const auto& p : points.points) {
    double best = 1e300;
    for (const auto& q : true_boundary_mm)
      best = std::min(best, (p.p_mm - q).squaredNorm());
    on_visible += best <= 1.5 * 1.5;
  }
  points.summary["fraction_on_visible_surface"] =
      static_cast<double>(on_visible) / points.points.size();
  spdlog::info(
      "ultrasound: points lie {:.2f} mm (median) from the true surface; {:.0f}% within 1.5 "
      "mm",
      d[d.size() / 2], 100 * within);
}

}  // namespace organfit::pipeline
