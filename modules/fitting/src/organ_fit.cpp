#include "organfit/fitting/organ_fit.h"

#include <Eigen/LU>
#include <Eigen/SVD>
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <optional>
#include <string>

#include "mapped_samples.h"
#include "organfit/fitting/embedded_body.h"
#include "organfit/fitting/global_map_posterior.h"
#include "organfit/geometry/mask_ops.h"
#include "organfit/geometry/signed_distance.h"
#include "organfit/particles/diagnostics.h"

namespace organfit::fitting {

double p95_tolerance_mm(double radius_mm, double mean_tolerance_mm) {
  // Half-normal residuals |n|, n ~ N(0, s^2): mean s sqrt(2 / pi), 95th percentile 1.96 s.
  constexpr double kP95OverMean = 1.959964 / 0.7978846;
  return std::max(radius_mm, kP95OverMean * mean_tolerance_mm);
}

namespace {

double body_volume(const particles::Positions& x, double rho, double voxel_mm) {
  return geometry::particle_body_volume_mm3(x, rho, voxel_mm, rho);
}

std::string volume_change_reason(double volume_ratio, double tolerance_pct) {
  char text[160];
  std::snprintf(text, sizeof text,
                "the local stage changed the organ's volume by %+.1f%% (more than %g%%)",
                100.0 * (volume_ratio - 1), tolerance_pct);
  return text;
}

/// Where the global maps `fits` disagree with `map`: at each surface sample's image by `map`,
/// the mean over `fits` of the square of each one's image of it from `map`'s, along `map`'s
/// normal there (its affine part's turn of the sample's normal), mm^2; empty where that is
/// 0 at every sample.
PriorVarianceField undecided_by(const GlobalMap& map, const std::vector<GlobalMap>& fits,
                                const SurfaceSamples& surface) {
  const Eigen::Index n = surface.points.cols();
  PriorVarianceField out;
  if (fits.empty() || n == 0) return out;
  out.at_mm.resize(3, n);
  out.variance_mm2.resize(n);
  const Eigen::Matrix3d normal_map = map.affine.a.inverse().transpose();
#pragma omp parallel for schedule(static)
  for (Eigen::Index j = 0; j < n; ++j) {
    const Eigen::Vector3d x = surface.points.col(j);
    const Eigen::Vector3d at = map.apply(x);
    const Eigen::Vector3d normal = (normal_map * surface.normals.col(j)).normalized();
    double sum = 0;
    for (const GlobalMap& fit : fits) {
      const double d = normal.dot(fit.apply(x) - at);
      sum += d * d;
    }
    out.at_mm.col(j) = at;
    out.variance_mm2[j] = sum / static_cast<double>(fits.size());
  }
  // No disagreement anywhere (the kept map alone, or fits that agree): u = 0, an empty
  // field, which the uncertainty need not look up and a model file need not carry.
  if (out.variance_mm2.maxCoeff() == 0) return PriorVarianceField{};
  return out;
}

/// Both fits: the measures before, the method's own stages (`paper` or `spread` set),
/// the fit loop, the undoing of a local stage that tore, folded or swelled the organ, the
/// measures after.
FittedOrgan fit_organ(OrganModel model, const std::vector<AttractivePoint>& points,
                      const OrganFitOptions& common, const PaperFitOptions* paper,
                      const SpreadFitOptions* spread, const FitObserver& observer) {
  FittedOrgan out;
  FitReport& report = out.report;
  report.method = paper ? "paper" : "spread";
  report.points = static_cast<int>(points.size());
  auto preparing = [&observer](int step, const std::string& done) {
    if (observer.preparing) observer.preparing(step, 6, done);
  };
  auto finishing = [&observer](int step, const std::string& done) {
    if (observer.finishing) observer.finishing(step, 4, done);
  };
  validate_points(points);
  particles::Model& m = *model.model;
  particles::State& state = model.state;
  const double rho = m.radius_mm();
  const particles::LennardJones law(model.cohesion);
  const double skin_voxel = common.skin_voxel_r0 * law.r0();

  // The organ before the fit, kept for measures against a truth after it; its volumes are
  // the model's own (measured at planning).
  const PlanningVolumes planned = planning_volumes(model);
  const double volume_voxel = planned.voxel_mm;
  report.volume_voxel_mm = volume_voxel;
  const particles::Positions start = state.x;
  // The pieces the body was planned in (particles within 1.5 r0 joined, as the planning
  // run counts them): the re-fill keeps as many, and only more after the fit is a tear.
  report.planning_pieces =
      state.size() > 0 ? particles::connected_components(start, 1.5 * law.r0()) : 1;
  out.before.emplace(organ_body(model));
  const double v0 = planned.particle_body_mm3;
  report.volume_before_mm3 = planned.organ_mm3;
  preparing(1, "the organ's volume before the fit");
  particles::IntegratorOptions opt = integrator_options_from(model.settings, m);
  opt.damping = common.damping_ratio * 2.0 * std::sqrt(law.stiffness() * m.mass());

  // The residual floor: a point exactly on the model's own surface is not at zero
  // residual, since the particles' surface is bumpy at their scale. Measured here on
  // dense samples of the reference surface against the model before the fit; the
  // tolerance on the mean residual is the stated one and this floor in quadrature.
  double residual_floor = 0;
  // The reference's signed distance, unsmoothed (the re-fill's depth; for an analytic
  // body it is the planning organ's, made by organ_body above) and smoothed (its surface
  // samples, and an analytic body's distance in the global fit).
  // Both are let go before the fit loop at the latest (8 bytes a reference voxel each: 640
  // MB apiece for a million-particle body's reference); the organ bodies keep the planning
  // organ's.
  std::shared_ptr<const geometry::SignedDistance> reference_exact =
      model.shape.mask || !model.planning_distance
          ? std::make_shared<const geometry::SignedDistance>(model.reference, false)
          : model.planning_distance;
  std::optional<const geometry::SignedDistance> smoothed_distance(reference_exact->smoothed());
  // Its surface samples, made once: every boundary voxel's for the spread fit (the surface
  // feet; one in 2 for the global map), one in 4 for the residual floor. The global fit
  // measures the points against a mask organ's own distance (below), so a mask organ's
  // smoothed reference distance is let go here, before the global stage's grids are made:
  // every byte of it is memory first touched at every session (75 MB on a 1.5 L liver).
  const SurfaceSamples reference_samples =
      reference_surface(model.reference, *smoothed_distance, spread ? 1 : 4);
  const bool organ_has_own_distance = model.shape.mask && model.shape.distance;
  if (organ_has_own_distance) smoothed_distance.reset();
  {
    SkinDetector skin0(skin_voxel, rho);
    skin0.update(start);
    const SurfaceSamples ref = spread ? reference_samples.one_in(4) : reference_samples;
    std::vector<AttractivePoint> probes;
    for (Eigen::Index j = 0; j < ref.points.cols(); ++j)
      probes.push_back({ref.points.col(j), 1.0});
    const std::vector<double> r = data_residuals(probes, start, skin0.skin(), rho);
    for (double v : r)
      residual_floor += v;
    residual_floor /= static_cast<double>(std::max<size_t>(1, r.size()));
  }
  report.residual_floor_mm = residual_floor;
  preparing(2, "the residual floor");

  FitOptions fo;
  fo.residual_mean_tolerance_mm = std::hypot(common.residual_tolerance_mm, residual_floor);
  fo.residual_max_tolerance_mm = common.residual_max_tolerance_mm > 0
                                     ? common.residual_max_tolerance_mm
                                     : p95_tolerance_mm(rho, fo.residual_mean_tolerance_mm);
  fo.kinetic_tolerance = common.kinetic_tolerance;
  fo.max_steps = common.max_steps;
  fo.max_wall_s = common.max_wall_s;
  fo.record_every = common.record_every;
  fo.volume = [&](const particles::Positions& x) { return body_volume(x, rho, volume_voxel); };
  fo.volume_every_rows = 1;
  fo.volume_at_start_mm3 = v0;  // the paper's fit starts from the model as it came
  report.residual_tolerance_mm = fo.residual_mean_tolerance_mm;
  report.residual_p95_tolerance_mm = fo.residual_max_tolerance_mm;

  particles::ForceTerm* data_term = nullptr;
  std::function<const std::vector<int>&(const particles::Positions&)> skin_of;
  std::function<void(particles::State&)> while_reaching;
  const std::vector<PointStatus>* status = nullptr;
  PriorVarianceField undecided;  // where the equally good global maps disagree (spread)
  if (paper) {
    auto& term =
        m.add(std::make_unique<PaperAttractiveForce>(points, law, rho, paper->force, skin_voxel));
    skin_of = [&term](const particles::Positions&) -> const std::vector<int>& {
      return term.skin().skin();
    };
    status = &term.status();
    data_term = &term;
  } else {
    // Global stage: a volume-preserving map of the whole organ (affine with det 1, then
    // quadratic shears and shear fields) fitted to the points; the body re-made in its
    // mapped shape.
    const auto started = std::chrono::steady_clock::now();
    const SurfaceSamples samples = reference_samples.one_in(2);
    AffineFitOptions global_options = spread->global;
    // The points' noise is what the fit accepts: the scale of fits equally good.
    global_options.noise_mm = spread->fit.residual_tolerance_mm;
    // The points are measured against the organ itself: for a mask organ, its own distance
    // at its level (the surface that is exported), smoothed within its slices as the
    // reference's is. The reference body, on a grid set by the particles' size, lies a few
    // tenths of a mm from it (0.26 mm RMS on a GTV at radius 3 mm), enough to put the organ
    // left as it was above the stated noise and let flexible maps fit the difference
    // (docs/decisions.md). An analytic body's reference is its organ.
    // Its single level, of all slice phases together: that smoothing evens out the phases.
    std::optional<const geometry::SignedDistance> organ_distance;
    if (organ_has_own_distance)
      organ_distance.emplace(
          model.shape.distance->smoothed_within_slices(model.shape.distance->volume_level()));
    std::vector<GlobalMap> equally_good;
    const GlobalMap map =
        fit_global_map(samples, points, global_options,
                       organ_distance ? &*organ_distance : &*smoothed_distance, &equally_good);
    if (map.refused) {
      report.refused = true;
      report.refused_move_mm = map.refused_move_mm;
      report.refused_stretch = map.refused_stretch;
      out.before.reset();
      out.model = std::move(model);
      return out;
    }
    preparing(3, "the global map");
    GlobalStageReport global;
    global.map = map;
    global.equally_good_fits = static_cast<int>(equally_good.size());
    undecided = undecided_by(map, equally_good, samples);
    global.equally_good_sd_mm =
        undecided.variance_mm2.size() > 0 ? std::sqrt(undecided.variance_mm2.mean()) : 0.0;
    // How far the points leave the map's affine part free (global_map_posterior.h): the
    // larger of that and the equally good maps' spread, place by place, is u(x)^2 (two
    // measures of one thing, the organ's place the points do not decide).
    const GlobalMapPosterior posterior = global_map_posterior(
        map, samples, points, global_options.noise_mm, common.unseen_motion_sd_mm,
        common.unseen_change_sd_mm, embedding_support_mm(model.lattice_spacing_mm),
        global_options.outlier_mads);
    global.posterior_sd_mm = std::sqrt(posterior.variance_mm2.mean());
    global.posterior_max_sd_mm = std::sqrt(posterior.variance_mm2.maxCoeff());
    if (undecided.variance_mm2.size() == 0) {
      undecided.at_mm = posterior.at_mm;
      undecided.variance_mm2 = posterior.variance_mm2;
    } else {
      undecided.variance_mm2 = undecided.variance_mm2.cwiseMax(posterior.variance_mm2);
    }
    model.global_map = map;
    if (model.skeleton) {
      m.remove(*model.skeleton);
      model.skeleton = nullptr;
    }
    // Re-fill the mapped reference and let its new surface settle; the settled surface
    // layer sits a little outside the lattice (more so for a larger surface), so the
    // count is corrected until the settled volume matches the model's (at most 3 passes).
    // As in planning (model_stage.cpp says why), the skeleton, made on each fill and tied
    // to it as made, holds the organ's shape while the surface settles; the settled body
    // becomes its rest shape.
    int count = state.size();
    int passes = 0;
    double settled_change_pct = 0;
    const MappedBodySites sites(model.reference, *reference_exact, model.lattice_spacing_mm, map);
    while (passes < 3) {
      ++passes;
      state = particles::State(sites.fill(count, report.planning_pieces));
      if (model.settings.skeleton) {
        if (model.skeleton) m.remove(*model.skeleton);
        const particles::Skeleton sk = particles::medial_skeleton(state.x, model.lattice_spacing_mm,
                                                                  model.skeleton_node_spacing_mm);
        model.skeleton =
            &m.add(std::make_unique<particles::SkeletonForce>(sk, state.x, model.skeleton_params));
      }
      particles::relax(m, state, opt, 300, common.kinetic_tolerance);
      const double v = body_volume(state.x, rho, volume_voxel);
      fo.volume_at_start_mm3 = v;  // the fit starts from the settled body
      settled_change_pct = 100.0 * (v - v0) / v0;
      if (std::abs(settled_change_pct) <= 0.25) break;
      count = static_cast<int>(std::lround(count * v0 / v));
    }
    preparing(4, "the body re-filled in its mapped shape (" + std::to_string(passes) + " passes)");
    global.principal_stretches = Eigen::JacobiSVD<Eigen::Matrix3d>(map.affine.a).singularValues();
    const MappedSamples mapped = map_samples(map, samples);  // once, for both measures
    global.moves = mapped.moves;
    global.shape_change_mm = shape_change_of(mapped.full, samples.points);
    global.organ_move_mm = (mapped.full - samples.points).rowwise().mean().norm();
    global.refill_passes = passes;
    global.particles_after_refill = state.size();
    global.volume_change_after_settling_pct = settled_change_pct;
    global.wall_s =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - started).count();
    report.global = global;
    if (model.skeleton) model.skeleton->set_rest_shape(state.x);
    preparing(5, "the skeleton");
    // Local stage: smooth patches; the skeleton's rest shape follows the fit until the
    // points are explained (it keeps the global shape between rows but does not pull the
    // body back to where it was), then stays (run_fit's while_reaching).
    auto& term =
        m.add(std::make_unique<SpreadAttractiveForce>(points, law, rho, spread->local, skin_voxel));
    // The surface the local stage fits is the organ's embedded surface (the reference
    // moved with the particles, embedded_body.h): each particle's foot on the mapped
    // reference surface and the tangent plane there replace the balls.
    fo.surface_feet =
        surface_feet(state.x, map_surface(map, reference_samples), 3.0 * model.lattice_spacing_mm);
    term.set_surface_feet(fo.surface_feet);
    skin_of = [&term](const particles::Positions&) -> const std::vector<int>& {
      return term.skin().skin();
    };
    status = &term.status();
    data_term = &term;
    if (model.skeleton) {
      while_reaching = [&model](particles::State& s) { model.skeleton->set_rest_shape(s.x); };
    }
  }

  smoothed_distance.reset();
  reference_exact.reset();
  preparing(6, "the surface feet");
  const particles::Positions placed = state.x;
  model.placed = state.x;
  report.fit = run_fit(m, state, opt, points, skin_of, status, fo, observer.row, while_reaching);
  if (report.global) report.fit.wall_s += report.global->wall_s;
  finishing(0, "the fit loop");

  // A local stage that tears the organ apart, or folds it (det(grad phi) <= 0 somewhere),
  // is undone: the organ the global stage made (placed: one piece, its volume kept, phi
  // the global map) is what is kept, and the fit has converged when that organ meets the
  // residual tolerances (the organ delivered is judged, not the stage undone). Seen on a
  // 10 x 8 x 6 mm organ of 0.3 mm particles under 0.5 mm noise (`organfit bench
  // stability`, tiny_radius): 32 particles pulled off its end, or, stopped before that, a
  // fold.
  auto undo_local_stage = [&](const std::string& why) {
    state = particles::State(placed);
    SkinDetector skin(skin_voxel, rho);
    skin.update(state.x);
    report.fit.residuals_mm =
        data_residuals(points, state.x, skin.skin(), rho, status, &fo.surface_feet);
    const ResidualSummary kept = summarise_residuals(report.fit.residuals_mm);
    report.fit.residual_mean_mm = kept.mean_mm;
    report.fit.residual_max_mm = kept.max_mm;
    report.fit.residual_p95_mm = kept.p95_mm;
    report.fit.converged = kept.mean_mm <= fo.residual_mean_tolerance_mm &&
                           kept.p95_mm <= fo.residual_max_tolerance_mm;
    report.fit.stop_reason = why + "; the global stage's organ kept" +
                             (report.fit.converged ? ", which explains the points" : "");
  };
  int pieces = report.planning_pieces;
  if (spread && state.size() > 0 &&
      (pieces = particles::connected_components(state.x, 1.5 * law.r0())) > report.planning_pieces)
    undo_local_stage("the local stage tore the organ into " + std::to_string(pieces) + " pieces (" +
                     std::to_string(report.planning_pieces) + " at planning)");
  report.pieces = pieces;
  finishing(1, "the pieces");
  auto make_organ_after = [&] {
    try {
      out.after.emplace(organ_body(model));
    } catch (const std::invalid_argument& e) {  // particles flung apart: not an input error
      throw ModelBrokeError(e.what());
    }
  };
  make_organ_after();
  if (spread && pieces <= report.planning_pieces && out.after->deformation().folds()) {
    undo_local_stage("the local stage folded the organ (det(grad phi) <= 0)");
    report.local_stage_folded = true;
    make_organ_after();
  }
  finishing(2, "the deformation");
  // The organ's volume change from the deformation's Jacobian over the fitted organ
  // (EmbeddedBody::volume_ratio: the grid's sampling cancels); the voxel count beside it.
  auto measure_organ_after = [&] {
    const geometry::LabelVolume organ_after_grid = out.after->on_grid(
        geometry::grid_covering(out.after->bounds(), volume_voxel, volume_voxel));
    report.volume_after_mm3 = organ_after_grid.volume_mm3(1);
    report.volume_ratio = out.after->volume_ratio(organ_after_grid);
  };
  measure_organ_after();
  // The local stage reshapes the organ and keeps its volume (the hold on its patches'
  // push); one that does not has not done its job: particles far smaller than the
  // points' noise are pulled by bumps of several diameters and the body swells.
  report.volume_tolerance_pct = common.volume_tolerance_pct;
  if (spread && !report.local_stage_undone() &&
      std::abs(100.0 * (report.volume_ratio - 1)) > common.volume_tolerance_pct) {
    undo_local_stage(volume_change_reason(report.volume_ratio, common.volume_tolerance_pct));
    report.local_stage_changed_volume = true;
    make_organ_after();
    measure_organ_after();
  }
  finishing(3, "the organ's volume");
  // The fit stopped right after a row that measured it, unless the local stage was undone.
  const double v1 = !report.local_stage_undone() && std::isfinite(report.fit.volume_at_end_mm3)
                        ? report.fit.volume_at_end_mm3
                        : body_volume(state.x, rho, volume_voxel);
  const Deformation& phi = out.after->deformation();
  report.deformation = out.after->shared_deformation();
  for (const auto& st : *status)
    report.rejected_points += st.rejected;
  // A fit that kept none of its points fitted nothing, whatever its loop said: the paper's
  // fit of points 600 mm off stopped "converged" at residual 0, every point rejected.
  if (report.rejected_every_point()) {
    report.fit.converged = false;
    report.fit.stop_reason = "every point rejected as an outlier: nothing was fitted";
  }
  report.particle_body_volume_change_pct = 100.0 * (v1 - v0) / v0;
  // The spread fit counted the pieces of this state already, unless its local stage was
  // undone (the state then is the global stage's).
  report.components = spread && state.size() > 0 && !report.local_stage_undone()
                          ? pieces
                          : particles::connected_components(state.x, 1.5 * law.r0());
  report.skin_particles = skin_of(state.x).size();
  report.finite = state.x.allFinite();
  // The uncertainty (surface_uncertainty.h): n the points' stated noise, r the model's
  // resolution (its residual floor: how far its own surface lies from the organ it was
  // made from), l the deformation's own support (one point informs the field that far), s^2 the
  // stated prior of unseen local change plus the mean square of the local change the points did
  // show (the part beyond the global map), and place by place u(x)^2, where the equally good global
  // maps disagree (undecided_by). Its observations are the points the fit used: a rejected
  // point (an outlier) neither pins the surface nor shows a change. Each observes the fitted
  // organ's residual there: the reference's signed distance d at phi^-1(p) less the organ's
  // level (mm), over the stretch of its normal into today's space by the global map's affine
  // part, |a^-T n|.
  std::vector<Eigen::Vector3d> point_positions;
  std::vector<double> point_residuals;
  double local_sq = 0;
  const geometry::SignedDistance& organ_distance = *out.after->shared_distance();
  const Eigen::Matrix3d normal_map = phi.global_map().affine.a.inverse().transpose();
  for (size_t k = 0; k < points.size(); ++k) {
    if (status && k < status->size() && (*status)[k].rejected) continue;
    const Eigen::Vector3d& p = points[k].p_mm;
    const Eigen::Vector3d x = phi.pull_back(p);
    point_positions.push_back(p);
    local_sq += (phi.global_map().apply(x) - p).squaredNorm();
    Eigen::Vector3d gradient;
    const double d = organ_distance.beyond_level(x, &gradient);
    const double stretch =
        gradient.norm() > 1e-9 ? (normal_map * gradient.normalized()).norm() : 1.0;
    point_residuals.push_back(d / stretch);
  }
  SurfaceUncertaintyOptions uo;
  const double s0 = common.unseen_change_sd_mm;
  const auto used = static_cast<double>(point_positions.size());
  uo.prior_sd_mm = std::sqrt(s0 * s0 + (used > 0 ? local_sq / used : 0.0));
  uo.length_mm = phi.support_mm();
  uo.noise_sd_mm = common.residual_tolerance_mm;
  uo.resolution_sd_mm = report.residual_floor_mm;
  report.uncertainty =
      std::make_shared<const SurfaceUncertainty>(point_positions, uo, point_residuals, undecided);
  finishing(4, "the uncertainty");
  // The data term is the fit's, not the model's: the model leaves with its own terms.
  m.remove(*data_term);
  out.model = std::move(model);
  return out;
}

}  // namespace

FittedOrgan fit_paper(OrganModel model, const std::vector<AttractivePoint>& points,
                      const PaperFitOptions& options, const FitObserver& observer) {
  return fit_organ(std::move(model), points, options.fit, &options, nullptr, observer);
}

FittedOrgan fit_spread(OrganModel model, const std::vector<AttractivePoint>& points,
                       const SpreadFitOptions& options, const FitObserver& observer) {
  return fit_organ(std::move(model), points, options.fit, nullptr, &options, observer);
}

}  // namespace organfit::fitting
