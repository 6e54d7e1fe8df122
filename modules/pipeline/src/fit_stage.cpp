#include "organfit/pipeline/fit_stage.h"

#include <fmt/format.h>
#include <spdlog/spdlog.h>

#include <Eigen/SVD>
#include <algorithm>
#include <cmath>
#include <fstream>
#include <sstream>

#include "organfit/fitting/embedded_body.h"
#include "organfit/fitting/global_fit.h"
#include "organfit/fitting/spread_force.h"
#include "organfit/geometry/mask_ops.h"
#include "organfit/geometry/signed_distance.h"
#include "organfit/meshing/surface.h"
#include "organfit/particles/diagnostics.h"
#include "organfit/support/error.h"
#include "organfit/support/interrupt.h"
#include "organfit/support/progress.h"
#include "organfit/support/resources.h"

namespace fs = std::filesystem;

namespace organfit::pipeline {

PointsTable read_points_file(const fs::path& file) {
  const std::string ext = file.extension().string();
  if (ext != ".ply" && ext != ".vtk" && ext != ".vtp") return read_points_table(file);
  PointsTable table;  // a mesh's vertices declare no CT
  for (const auto& p : meshing::read_point_set(file)) {
    if (!(std::isfinite(p[0]) && std::isfinite(p[1]) && std::isfinite(p[2])))
      throw InputError(file.string() + ": a point has a non-finite coordinate");
    if (!(p[3] > 0 && p[3] <= 1))
      throw InputError(file.string() + ": a confidence is outside (0, 1]");
    table.points.push_back({Eigen::Vector3d(p[0], p[1], p[2]), p[3]});
  }
  if (table.points.empty()) throw InputError(file.string() + ": no points in the file");
  return table;
}

evaluation::Deformation deformation_from(const config::Scene& scene,
                                         const evaluation::Shape& shape) {
  evaluation::Deformation d;
  d.stretch = scene.number("points", "stretch");
  d.bend_mm = scene.number("points", "bend_mm");
  d.twist_rad = scene.number("points", "twist_deg") * M_PI / 180;
  d.indent_mm = scene.number("points", "indent_mm");
  d.push_mm = scene.number("points", "push_mm");
  d.bump_sigma_mm = scene.number("points", "bump_sigma_mm");
  d.centre_mm = shape.centre_mm;
  d.half_length_mm = 0.5 * shape.size_mm.x() * d.stretch;
  return d;
}

PointsStageResult run_points_stage(const config::Scene& scene, const ModelStageResult& model) {
  PointsStageResult r;
  if (scene.text("points", "source") == "file") {
    PointsTable table = read_points_file(scene.path("points", "file"));
    r.points = std::move(table.points);
    r.declared_ct = table.ct;
    r.summary = {{"source", "file"}, {"count", r.points.size()}};
    return r;
  }
  // The shape the points come from: the body itself, or another of the same volume.
  r.truth_shape = model.shape;
  const std::string target = scene.text("points", "target_shape");
  if (target != "same") {
    evaluation::Shape t = evaluation::make_shape(target, scene.vec3("points", "target_size_mm"),
                                                 model.shape.centre_mm);
    const double voxel = 0.25 * model.cohesion.r0_mm;
    const double scale = std::cbrt(evaluation::shape_volume_mm3(model.shape, voxel) /
                                   evaluation::shape_volume_mm3(t, voxel));
    t.size_mm *= scale;
    r.truth_shape = t;
  }
  const evaluation::Deformation d = deformation_from(scene, r.truth_shape);
  evaluation::SamplingOptions o;
  o.count = static_cast<int>(scene.integer("points", "count"));
  o.noise_mm = scene.number("points", "noise_mm");
  o.outlier_fraction = scene.number("points", "outlier_fraction");
  o.half_coverage = scene.text("points", "coverage") == "half";
  o.seed = static_cast<unsigned>(scene.integer("scene", "seed"));
  r.points = evaluation::sample_deformed_surface(r.truth_shape, d, o);
  r.truth = d;
  r.summary = {{"source", "generate"},
               {"count", r.points.size()},
               {"noise_mm", o.noise_mm},
               {"outlier_fraction", o.outlier_fraction},
               {"coverage", scene.text("points", "coverage")},
               {"stretch", d.stretch},
               {"bend_mm", d.bend_mm},
               {"twist_rad", d.twist_rad},
               {"indent_mm", d.indent_mm},
               {"push_mm", d.push_mm},
               {"target_shape", r.truth_shape.kind},
               {"target_size_mm",
                {r.truth_shape.size_mm.x(), r.truth_shape.size_mm.y(), r.truth_shape.size_mm.z()}}};
  return r;
}

namespace {

/// Voxel (mm) of the volume measures made in every fit: half the particle radius, but
/// coarse enough that the organ holds at most about 8 million voxels (a voxel count's
/// error is about its surface voxels over its volume: 0.1% there), so that a model of
/// small particles in a large organ is not measured on a grid of 10^8 voxels.
double volume_voxel_mm(double rho, double organ_volume_mm3) {
  return std::max(0.5 * rho, std::cbrt(organ_volume_mm3 / 8e6));
}

double body_volume(const particles::Positions& x, double rho, double voxel_mm) {
  return geometry::particle_body_volume_mm3(x, rho, voxel_mm, rho);
}

}  // namespace

geometry::Aabb deformed_bounds(const evaluation::Shape& s, const evaluation::Deformation& d) {
  const geometry::Aabb b = s.bounds();
  geometry::Aabb out{Eigen::Vector3d::Constant(1e300), Eigen::Vector3d::Constant(-1e300)};
  for (int c = 0; c < 8; ++c) {
    const Eigen::Vector3d corner((c & 1) ? b.max_mm.x() : b.min_mm.x(),
                                 (c & 2) ? b.max_mm.y() : b.min_mm.y(),
                                 (c & 4) ? b.max_mm.z() : b.min_mm.z());
    const Eigen::Vector3d q = d.apply(corner);
    out.min_mm = out.min_mm.cwiseMin(q);
    out.max_mm = out.max_mm.cwiseMax(q);
  }
  // The non-affine parts move points off the corners' hull by at most their amplitudes.
  const double margin = std::abs(d.bend_mm) + std::abs(d.indent_mm) + std::abs(d.push_mm) +
                        std::abs(d.twist_rad) * 0.5 * (b.max_mm - b.min_mm).maxCoeff() +
                        (d.field ? d.field->largest_mm : 0.0);
  out.min_mm.array() -= margin;
  out.max_mm.array() += margin;
  return out;
}

UncertaintyOnSurface uncertainty_on_surface(const evaluation::Shape& planning,
                                            const fitting::Deformation& phi,
                                            const fitting::SurfaceUncertainty& u) {
  UncertaintyOnSurface r;
  evaluation::SamplingOptions so;
  so.count = 4000;
  so.noise_mm = 0;
  const auto samples = evaluation::sample_deformed_surface(planning, evaluation::Deformation{}, so);
  const auto n = static_cast<long>(samples.size());
  r.surface.resize(samples.size());
  r.sigma.resize(samples.size());
  r.nearest.resize(samples.size());
#pragma omp parallel for schedule(dynamic, 64)
  for (long i = 0; i < n; ++i) {
    const auto k = static_cast<size_t>(i);
    r.surface[k] = phi.push_forward(samples[k].p_mm);
    r.sigma[k] = u.sd_mm(r.surface[k]);
    r.nearest[k] = u.nearest_point_mm(r.surface[k]);
  }
  std::vector<double> by_distance = r.nearest;
  std::nth_element(by_distance.begin(), by_distance.begin() + by_distance.size() / 2,
                   by_distance.end());
  r.split_mm = by_distance.empty() ? 0.0 : by_distance[by_distance.size() / 2];
  auto quantiles = [&](int half) {  // -1: all, 0: seen, 1: unseen
    std::vector<double> v;
    for (size_t i = 0; i < r.sigma.size(); ++i)
      if (half < 0 || r.unseen(i) == (half == 1)) v.push_back(r.sigma[i]);
    std::sort(v.begin(), v.end());
    auto q = [&v](double f) {
      return v.empty() ? 0.0 : v[static_cast<size_t>(f * (v.size() - 1))];
    };
    return nlohmann::json{{"median_mm", q(0.5)}, {"p95_mm", q(0.95)}};
  };
  const auto& o = u.options();
  r.summary = {{"method", "Gaussian-process posterior of the surface's normal error"},
               {"prior_sd_mm", o.prior_sd_mm},
               {"length_mm", o.length_mm},
               {"noise_sd_mm", o.noise_sd_mm},
               {"surface_samples", r.sigma.size()},
               {"seen_half_within_mm", r.split_mm},
               {"all", quantiles(-1)},
               {"seen", quantiles(0)},
               {"unseen", quantiles(1)}};
  return r;
}

nlohmann::json uncertainty_coverage(const UncertaintyOnSurface& s,
                                    const std::function<bool(const Eigen::Vector3d&)>& truth_inside,
                                    const geometry::Aabb& truth_bounds, double voxel_mm) {
  geometry::LabelVolume truth(geometry::grid_covering(truth_bounds, voxel_mm, 4 * voxel_mm));
  const auto& g = truth.geometry;
#pragma omp parallel for schedule(dynamic)
  for (int k = 0; k < g.size[2]; ++k)
    for (int j = 0; j < g.size[1]; ++j)
      for (int i = 0; i < g.size[0]; ++i)
        truth.at(i, j, k) = truth_inside(g.index_to_physical(Eigen::Vector3d(i, j, k)));
  const geometry::SignedDistance to_truth(truth, false);
  int within[3] = {0, 0, 0}, count[3] = {0, 0, 0};
  for (size_t i = 0; i < s.surface.size(); ++i) {
    const bool ok = std::abs(to_truth.at(s.surface[i])) <= 2 * s.sigma[i];
    const int half = s.unseen(i) ? 2 : 1;
    within[0] += ok, ++count[0], within[half] += ok, ++count[half];
  }
  auto share = [&](int h) { return count[h] ? double(within[h]) / count[h] : 0.0; };
  return {{"within_2sd_share", share(0)},
          {"seen_within_2sd_share", share(1)},
          {"unseen_within_2sd_share", share(2)}};
}

FitStageResult run_fit_stage(const config::Scene& scene, ModelStageResult& model,
                             const PointsStageResult& pts) {
  FitStageResult out;
  const std::string method = scene.text("fit", "method");
  particles::Model& m = *model.model;
  particles::State& state = model.state;
  const double rho = m.radius_mm();
  const particles::LennardJones law(model.cohesion);
  const double skin_voxel = scene.number("fit", "skin_voxel_r0") * law.r0();
  const auto& points = pts.points;
  try {
    fitting::validate_points(points);
  } catch (const std::invalid_argument& e) {
    throw InputError(std::string("points: ") + e.what());
  }

  // The organ before the fit, kept for the truth report after it (measured then: an
  // interrupt during the fit is answered at once, not after the truth's grids).
  const double truth_voxel = evaluation::kTruthVoxelMm;
  const double volume_voxel = volume_voxel_mm(rho, model.reference.volume_mm3(1));
  const particles::Positions start = state.x;
  // The steps before the fit loop (seconds on a large organ), shown as one progress.
  Progress preparing("fit: preparing", 6);
  const fitting::EmbeddedBody organ_before = organ_body(model);
  const double v0 = body_volume(start, rho, volume_voxel);
  const double organ_v0 = organ_before.volume_mm3(volume_voxel);

  preparing.update(1, "the organ's volume before the fit");
  particles::IntegratorOptions opt = integrator_options_from(model.settings, m);
  opt.damping = scene.number("fit", "damping_ratio") * 2.0 * std::sqrt(law.stiffness() * m.mass());

  // The residual floor: a point exactly on the model's own surface is not at zero
  // residual, since the particles' surface is bumpy at their scale. Measured here on
  // dense samples of the reference surface against the model before the fit; the
  // tolerance on the mean residual is the stated one and this floor in quadrature.
  double residual_floor = 0;
  const geometry::SignedDistance reference_distance(model.reference);
  {
    fitting::SkinDetector skin0(skin_voxel, rho);
    skin0.update(start);
    const fitting::SurfaceSamples ref =
        fitting::reference_surface(model.reference, reference_distance, 4);
    std::vector<fitting::AttractivePoint> probes;
    for (Eigen::Index j = 0; j < ref.points.cols(); ++j)
      probes.push_back({ref.points.col(j), 1.0});
    const std::vector<double> r = fitting::data_residuals(probes, start, skin0.skin(), rho);
    for (double v : r)
      residual_floor += v;
    residual_floor /= std::max<size_t>(1, r.size());
  }
  const double tolerance = scene.number("fit", "residual_tolerance_mm");
  preparing.update(2, "the residual floor");

  fitting::FitOptions fo;
  fo.residual_mean_tolerance_mm = std::hypot(tolerance, residual_floor);
  fo.residual_max_tolerance_mm = scene.number("fit", "residual_max_tolerance_mm");
  fo.kinetic_tolerance = scene.number("fit", "kinetic_tolerance");
  fo.max_steps = scene.integer("fit", "max_steps");
  fo.max_wall_s = scene.number("fit", "max_wall_s");
  fo.record_every = static_cast<int>(scene.integer("fit", "record_every"));
  fo.volume = [&](const particles::Positions& x) { return body_volume(x, rho, volume_voxel); };
  fo.volume_every_rows = 1;

  Stopwatch clock;
  nlohmann::json global = nullptr;
  std::function<const std::vector<int>&(const particles::Positions&)> skin_of;
  std::function<void(particles::State&)> after_row;
  const std::vector<fitting::PointStatus>* status = nullptr;
  if (method == "paper") {
    fitting::PaperForceParams pp;
    pp.alpha = scene.number("fit", "alpha");
    pp.influence_radius_min_r0 = scene.number("fit", "influence_radius_min_r0");
    pp.influence_growth = scene.number("fit", "influence_growth");
    pp.influence_radius_max_r0 = scene.number("fit", "influence_radius_max_r0");
    pp.total_force_factor = scene.number("fit", "total_force_factor");
    pp.outlier_distance_mm = scene.number("fit", "outlier_distance_mm");
    auto& term =
        m.add(std::make_unique<fitting::PaperAttractiveForce>(points, law, rho, pp, skin_voxel));
    skin_of = [&term](const particles::Positions&) -> const std::vector<int>& {
      return term.skin().skin();
    };
    status = &term.status();
  } else {
    // Global stage: a volume-preserving map of the whole organ (affine with det 1, then
    // quadratic shears) fitted to the points; the body re-made in its mapped shape.
    const fitting::SurfaceSamples samples =
        fitting::reference_surface(model.reference, reference_distance, 2);
    fitting::AffineFitOptions global_options;
    global_options.max_stretch = scene.number("fit", "max_global_stretch");
    global_options.field_sigma_mm = scene.number("fit", "global_shear_field_mm");
    global_options.noise_mm = tolerance;
    const fitting::GlobalMap map =
        fitting::fit_global_map(samples, points, global_options, &reference_distance);
    if (map.refused) {
      throw TargetNotMetError(fmt::format(
          "fit: the points ask for an implausible change of the whole organ (a stretch beyond {}x, "
          "fit.max_global_stretch, or a bend beyond a quarter of its size); check that they belong "
          "to this organ and are in the same patient coordinates",
          global_options.max_stretch));
    }
    const fitting::AffineFit& affine = map.affine;
    preparing.update(3, "the global map");
    out.global_map = map;
    model.global_map = map;
    if (model.skeleton) {
      m.remove(*model.skeleton);
      model.skeleton = nullptr;
    }
    // Re-fill the mapped reference and let its new surface settle; the settled surface
    // layer sits a little outside the lattice (more so for a larger surface), so the
    // count is corrected until the settled volume matches the model's (at most 3 passes).
    int count = state.size();
    int passes = 0;
    double settled_change_pct = 0;
    while (passes < 3) {
      ++passes;
      state = particles::State(
          fitting::refill_mapped_body(model.reference, count, model.lattice_spacing_mm, map));
      particles::relax(m, state, opt, 300, scene.number("fit", "kinetic_tolerance"));
      const double v = body_volume(state.x, rho, volume_voxel);
      settled_change_pct = 100.0 * (v - v0) / v0;
      spdlog::debug("fit: re-fill pass {}: {} particles asked, {} placed, settled volume {:+.2f}%",
                    passes, count, state.size(), settled_change_pct);
      if (std::abs(settled_change_pct) <= 0.25) break;
      count = static_cast<int>(std::lround(count * v0 / v));
    }
    preparing.update(4, fmt::format("the body re-filled in its mapped shape ({} passes)", passes));
    const Eigen::Vector3d stretches = Eigen::JacobiSVD<Eigen::Matrix3d>(affine.a).singularValues();
    const fitting::LargestMoves moves = fitting::largest_moves(map, samples);
    global = {{"rms_before_mm", affine.rms_before_mm},
              {"rms_after_mm", map.rms_after_mm},
              {"iterations", affine.iterations},
              {"principal_stretches", {stretches.x(), stretches.y(), stretches.z()}},
              {"translation_mm", {affine.t.x(), affine.t.y(), affine.t.z()}},
              {"shear_coefficients_per_mm",
               std::vector<double>(map.shears.c.data(), map.shears.c.data() + map.shears.c.size())},
              {"shears_dropped", map.shears_dropped},
              {"shear_fields_sigma_mm", map.fields.empty() ? 0.0 : map.fields.sigma_mm},
              {"shears_largest_move_mm", moves.shears_mm},
              {"shear_fields_largest_move_mm", moves.fields_mm},
              {"found_by", map.found_by},
              {"shape_change_mm", fitting::shape_change_mm(map, samples)},
              {"refill_passes", passes},
              {"particles_after_refill", state.size()},
              {"volume_change_after_settling_pct", settled_change_pct},
              {"wall_s", clock.elapsed_s()}};
    if (model.settings.skeleton) {
      const particles::Skeleton sk = particles::medial_skeleton(state.x, model.lattice_spacing_mm,
                                                                model.skeleton_node_spacing_mm);
      model.skeleton =
          &m.add(std::make_unique<particles::SkeletonForce>(sk, state.x, model.skeleton_params));
    }
    preparing.update(5, "the skeleton");
    // Local stage: smooth patches; the skeleton's rest shape follows the fit (it keeps
    // the global shape between rows but does not pull the body back to where it was).
    auto& term = m.add(std::make_unique<fitting::SpreadAttractiveForce>(
        points, law, rho, fitting::SpreadForceParams{}, skin_voxel));
    // The surface the local stage fits is the organ's embedded surface (the reference
    // moved with the particles, fitting/embedded_body.h): each particle's foot on the
    // mapped reference surface and the tangent plane there replace the balls.
    fo.surface_feet = fitting::surface_feet(
        state.x,
        fitting::map_surface(map,
                             fitting::reference_surface(model.reference, reference_distance, 1)),
        3.0 * model.lattice_spacing_mm);
    term.set_surface_feet(fo.surface_feet);
    skin_of = [&term](const particles::Positions&) -> const std::vector<int>& {
      return term.skin().skin();
    };
    status = &term.status();
    if (model.skeleton) {
      after_row = [&model](particles::State& s) { model.skeleton->set_rest_shape(s.x); };
    }
  }

  preparing.update(6, "the surface feet");
  preparing.finish();
  out.placed = state.x;
  model.placed = state.x;
  Progress progress("fit", fo.max_steps);
  out.fit = fitting::run_fit(
      m, state, opt, points, skin_of, status, fo,
      [&](const fitting::HistoryRow& h) {
        throw_if_interrupted();
        progress.update(h.step, fmt::format("residual {:.2f} mm", h.residual_mean_mm));
      },
      after_row);
  progress.finish();
  out.fit.wall_s += global.is_null() ? 0.0 : global["wall_s"].get<double>();

  // A local stage that tears the organ apart is undone: the organ the global stage made
  // (out.placed: one piece, its volume kept) is what is kept, and the fit reports it did
  // not converge. Seen on a 10 x 8 x 6 mm organ of 0.3 mm particles under 0.5 mm noise
  // (`organfit bench stability`, tiny_radius): 32 particles pulled off its end.
  int pieces = 1;
  if (method == "spread" && state.size() > 0 &&
      (pieces = particles::connected_components(state.x, 1.5 * law.r0())) > 1) {
    spdlog::warn(
        "fit: the local stage tore the organ into {} pieces; the global stage's organ is kept",
        pieces);
    state = particles::State(out.placed);
    fitting::SkinDetector skin(skin_voxel, rho);
    skin.update(state.x);
    out.fit.residuals_mm =
        fitting::data_residuals(points, state.x, skin.skin(), rho, status, &fo.surface_feet);
    const fitting::ResidualSummary kept = fitting::summarise_residuals(out.fit.residuals_mm);
    out.fit.residual_mean_mm = kept.mean_mm;
    out.fit.residual_max_mm = kept.max_mm;
    out.fit.residual_p95_mm = kept.p95_mm;
    out.fit.converged = false;
    out.fit.stop_reason = fmt::format(
        "the local stage tore the organ into {} pieces; the global stage's organ kept", pieces);
  }

  const double v1 = body_volume(state.x, rho, volume_voxel);
  const fitting::EmbeddedBody organ_after = [&] {
    try {
      return organ_body(model);
    } catch (const std::invalid_argument& e) {  // particles flung apart: not an input error
      throw TargetNotMetError(std::string("fit: the model did not hold together: ") + e.what());
    }
  }();
  // The organ's volume change from the deformation's Jacobian over the fitted organ
  // (EmbeddedBody::volume_ratio: the grid's sampling cancels); the two voxel counts are
  // reported beside it.
  const geometry::LabelVolume organ_after_grid = organ_after.on_grid(
      geometry::grid_covering(organ_after.bounds(), volume_voxel, volume_voxel));
  const double organ_v1 = organ_after_grid.volume_mm3(1);
  const double volume_ratio = organ_after.volume_ratio(organ_after_grid);
  const fitting::Deformation& phi = organ_after.deformation();
  out.deformation_folds = phi.folds();
  out.deformation = organ_after.shared_deformation();
  int rejected = 0;
  for (const auto& st : *status)
    rejected += st.rejected;
  out.fit_summary = {{"method", method},
                     {"attractive_points", points.size()},
                     {"rejected_points", rejected},
                     {"iterations", out.fit.steps},
                     {"wall_s", out.fit.wall_s},
                     {"instrument_wall_s", out.fit.instrument_wall_s},
                     {"converged", out.fit.converged},
                     {"stop_reason", out.fit.stop_reason},
                     {"local_stage_undone", pieces > 1},
                     {"residual_mean_mm", out.fit.residual_mean_mm},
                     {"residual_floor_mm", residual_floor},
                     {"residual_tolerance_mm", fo.residual_mean_tolerance_mm},
                     {"residual_max_mm", out.fit.residual_max_mm},
                     {"residual_p95_mm", out.fit.residual_p95_mm},
                     {"volume_before_mm3", organ_v0},
                     {"volume_after_mm3", organ_v1},
                     {"volume_change_pct", 100.0 * (volume_ratio - 1)},
                     {"volume_change_counted_pct", 100.0 * (organ_v1 - organ_v0) / organ_v0},
                     {"deformation",
                      {{"min_volume_ratio", phi.min_volume_ratio()},
                       {"max_volume_ratio", phi.max_volume_ratio()},
                       {"lattice_mm", phi.support_mm() / 4},
                       {"fitted_nodes", phi.fitted_nodes()},
                       {"harmonic_nodes", phi.harmonic_nodes()},
                       {"folds", phi.folds()}}},
                     {"particle_body_volume_change_pct", 100.0 * (v1 - v0) / v0},
                     {"components", particles::connected_components(state.x, 1.5 * law.r0())},
                     {"skin_particles", skin_of(state.x).size()},
                     {"finite", state.x.allFinite()}};
  if (!global.is_null()) out.fit_summary["global"] = global;
  // The uncertainty (fitting/surface_uncertainty.h): n the noise the fit accepts, l the
  // deformation's own support (one point informs the field that far), s^2 the stated
  // prior of unseen local change plus the mean square of the local change the points
  // did show (the part beyond the global map).
  std::vector<Eigen::Vector3d> point_positions;
  double local_sq = 0;
  for (const auto& p : points) {
    point_positions.push_back(p.p_mm);
    local_sq += (phi.global_map().apply(phi.pull_back(p.p_mm)) - p.p_mm).squaredNorm();
  }
  fitting::SurfaceUncertaintyOptions uo;
  const double s0 = scene.number("fit", "unseen_change_sd_mm");
  uo.prior_sd_mm = std::sqrt(s0 * s0 + (points.empty() ? 0.0 : local_sq / points.size()));
  uo.length_mm = phi.support_mm();
  uo.noise_sd_mm = fo.residual_mean_tolerance_mm;
  out.uncertainty = std::make_shared<const fitting::SurfaceUncertainty>(point_positions, uo);
  const UncertaintyOnSurface on_surface =
      uncertainty_on_surface(model.shape, phi, *out.uncertainty);
  out.fit_summary["uncertainty"] = on_surface.summary;
  if (pts.truth && scene.flag("fit", "measure_truth")) {
    spdlog::info("fit: done in {} steps; measuring it against the known deformation ({} mm grid)",
                 out.fit.steps, truth_voxel);
    Stopwatch truth_clock;
    Progress truth_progress("truth", 4);
    // The discretisation floor (the organ as the model carried it before the fit against
    // the shape it was made from), the undeformed error, and the fit's.
    const auto floor = evaluation::compare_with_body(
        organ_before, [&](const Eigen::Vector3d& p) { return model.shape.inside(p); },
        model.shape.bounds(), truth_voxel);
    throw_if_interrupted();
    truth_progress.update(1, "the model before the fit against its shape");
    const auto undeformed = evaluation::compare_with_body(
        organ_before, evaluation::deformed_inside(pts.truth_shape, *pts.truth),
        deformed_bounds(pts.truth_shape, *pts.truth), truth_voxel);
    throw_if_interrupted();
    truth_progress.update(2, "the organ left undeformed");
    const auto fitted = evaluation::compare_with_body(
        organ_after, evaluation::deformed_inside(pts.truth_shape, *pts.truth),
        deformed_bounds(pts.truth_shape, *pts.truth), truth_voxel);
    throw_if_interrupted();
    truth_progress.update(3, "the fitted organ");
    const auto fitted_balls = evaluation::compare_with_body(
        state.x, rho, evaluation::deformed_inside(pts.truth_shape, *pts.truth),
        deformed_bounds(pts.truth_shape, *pts.truth), truth_voxel);
    truth_progress.update(4, "the fitted particles' balls");
    truth_progress.finish();
    const double denom = undeformed.msd_mm - floor.msd_mm;
    out.truth_summary = {
        {"msd_mm", fitted.msd_mm},
        {"hd95_mm", fitted.hd95_mm},
        {"dice", fitted.dice},
        {"msd_undeformed_mm", undeformed.msd_mm},
        {"hd95_undeformed_mm", undeformed.hd95_mm},
        {"msd_floor_mm", floor.msd_mm},
        {"recovery", denom > 0 ? (undeformed.msd_mm - fitted.msd_mm) / denom : 0.0},
        {"voxel_mm", truth_voxel},
        {"surface", "the reference moved with the particles (fitting/embedded_body.h)"},
        {"particle_balls",
         {{"msd_mm", fitted_balls.msd_mm},
          {"hd95_mm", fitted_balls.hd95_mm},
          {"dice", fitted_balls.dice}}}};
    // On the organ's own volume grid (rho/2, coarser for a large organ: at most about 8M
    // voxels), not the truth's 0.5 mm: a 2.3 L lung's true organ at 0.5 mm took 1.4 GB.
    out.truth_summary["uncertainty"] =
        uncertainty_coverage(on_surface, evaluation::deformed_inside(pts.truth_shape, *pts.truth),
                             deformed_bounds(pts.truth_shape, *pts.truth), volume_voxel);
    out.truth_summary["uncertainty"]["voxel_mm"] = volume_voxel;
    out.truth_wall_s = truth_clock.elapsed_s();
    out.truth_summary["wall_s"] = out.truth_wall_s;
  }
  std::ostringstream csv;
  csv << "step,wall_s,residual_mean_mm,residual_max_mm,volume_change_pct,kinetic_energy_per_"
         "particle\n";
  for (const auto& h : out.fit.history) {
    csv << fmt::format("{},{:.6f},{:.6f},{:.6f},{},{:.6g}\n", h.step, h.wall_s, h.residual_mean_mm,
                       h.residual_max_mm,
                       std::isnan(h.volume_change_pct) ? std::string()
                                                       : fmt::format("{:.4f}", h.volume_change_pct),
                       h.kinetic_energy_per_particle);
  }
  out.history_csv = csv.str();
  if (!out.fit.converged) {
    std::vector<std::pair<double, int>> worst;
    for (size_t k = 0; k < out.fit.residuals_mm.size(); ++k)
      worst.push_back({out.fit.residuals_mm[k], static_cast<int>(k)});
    std::sort(worst.rbegin(), worst.rend());
    int far = 0;
    for (const auto& [r, k] : worst)
      far += r > rho;
    std::string list;
    for (size_t w = 0; w < std::min<size_t>(5, worst.size()); ++w)
      list += fmt::format("{}#{} ({:.2f} mm)", w ? ", " : "", worst[w].second, worst[w].first);
    out.not_converged_message = fmt::format(
        "fit did not converge ({}): mean residual {:.2f} mm (tolerance {:.2f}), {} of {} points "
        "farther than "
        "{:.2f} mm; worst: {}",
        out.fit.stop_reason, out.fit.residual_mean_mm, fo.residual_mean_tolerance_mm, far,
        points.size(), rho, list);
  }
  if (out.deformation_folds)
    out.not_converged_message =
        (out.not_converged_message.empty() ? "" : out.not_converged_message + "; ") +
        "the fitted deformation folds (det(grad phi) <= 0 near the organ): nothing is exported";
  return out;
}

}  // namespace organfit::pipeline
