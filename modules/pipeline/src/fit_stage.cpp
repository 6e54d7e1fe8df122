#include "organfit/pipeline/fit_stage.h"

#include <fmt/format.h>
#include <spdlog/spdlog.h>

#include <algorithm>
#include <cmath>
#include <optional>
#include <sstream>

#include "organfit/fitting/embedded_body.h"
#include "organfit/fitting/global_fit.h"
#include "organfit/geometry/mask_ops.h"
#include "organfit/geometry/signed_distance.h"
#include "organfit/pipeline/scene_schema.h"
#include "organfit/support/error.h"
#include "organfit/support/interrupt.h"
#include "organfit/support/progress.h"
#include "organfit/support/resources.h"

namespace fs = std::filesystem;

namespace organfit::pipeline {

UncertaintyOnSurface uncertainty_on_surface(const geometry::Shape& planning,
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
  r.summary = {{"method",
                "root mean square of the surface's normal error about the fitted surface: a "
                "Gaussian-process posterior given the fit's residuals at the points"},
               {"prior_sd_mm", o.prior_sd_mm},
               {"length_mm", o.length_mm},
               {"noise_sd_mm", o.noise_sd_mm},
               {"resolution_sd_mm", o.resolution_sd_mm},
               {"far_sd_mm", u.far_sd_mm()},
               {"surface_samples", r.sigma.size()},
               {"seen_half_within_mm", r.split_mm},
               {"all", quantiles(-1)},
               {"seen", quantiles(0)},
               {"unseen", quantiles(1)}};
  return r;
}

nlohmann::json uncertainty_coverage(const UncertaintyOnSurface& s,
                                    const evaluation::InsideTest& truth,
                                    const geometry::Aabb& truth_bounds, double voxel_mm) {
  // The true organ's signed distance at the surface samples alone, not on its whole grid.
  Eigen::Matrix3Xd at(3, static_cast<Eigen::Index>(s.surface.size()));
  for (size_t i = 0; i < s.surface.size(); ++i)
    at.col(static_cast<Eigen::Index>(i)) = s.surface[i];
  const std::vector<double> to_truth = geometry::signed_distance_at(
      evaluation::sample_inside(truth,
                                geometry::grid_covering(truth_bounds, voxel_mm, 4 * voxel_mm)),
      at);
  int within[3] = {0, 0, 0}, count[3] = {0, 0, 0};
  for (size_t i = 0; i < s.surface.size(); ++i) {
    const bool ok = std::abs(to_truth[i]) <= 2 * s.sigma[i];
    const int half = s.unseen(i) ? 2 : 1;
    within[0] += ok, ++count[0], within[half] += ok, ++count[half];
  }
  auto share = [&](int h) { return count[h] ? double(within[h]) / count[h] : 0.0; };
  return {{"within_2sd_share", share(0)},
          {"seen_within_2sd_share", share(1)},
          {"unseen_within_2sd_share", share(2)}};
}

fitting::OrganFitOptions organ_fit_options_from(const config::Scene& scene) {
  return keys::fit().read(scene);
}

fitting::PaperFitOptions paper_fit_options_from(const config::Scene& scene) {
  return {organ_fit_options_from(scene), keys::fit_paper().read(scene)};
}

fitting::SpreadFitOptions spread_fit_options_from(const config::Scene& scene) {
  return {organ_fit_options_from(scene), keys::fit_spread_global().read(scene),
          keys::fit_spread_local().read(scene)};
}

nlohmann::json fit_summary(const fitting::FitReport& r) {
  const fitting::Deformation& phi = *r.deformation;
  nlohmann::json j = {{"method", r.method},
                      {"attractive_points", r.points},
                      {"rejected_points", r.rejected_points},
                      {"iterations", r.fit.steps},
                      {"wall_s", r.fit.wall_s},
                      {"instrument_wall_s", r.fit.instrument_wall_s},
                      {"steps_wall_s", r.fit.steps_wall_s},
                      {"converged", r.fit.converged},
                      {"stop_reason", r.fit.stop_reason},
                      {"explained_at_step", r.fit.explained_at_step},
                      {"local_stage_undone", r.local_stage_undone()},
                      {"residual_mean_mm", r.fit.residual_mean_mm},
                      {"residual_floor_mm", r.residual_floor_mm},
                      {"residual_tolerance_mm", r.residual_tolerance_mm},
                      {"residual_p95_tolerance_mm", r.residual_p95_tolerance_mm},
                      {"residual_max_mm", r.fit.residual_max_mm},
                      {"residual_p95_mm", r.fit.residual_p95_mm},
                      {"volume_before_mm3", r.volume_before_mm3},
                      {"volume_after_mm3", r.volume_after_mm3},
                      {"volume_change_pct", 100.0 * (r.volume_ratio - 1)},
                      {"volume_tolerance_pct", r.volume_tolerance_pct},
                      {"volume_change_counted_pct",
                       100.0 * (r.volume_after_mm3 - r.volume_before_mm3) / r.volume_before_mm3},
                      {"deformation",
                       {{"min_volume_ratio", phi.min_volume_ratio()},
                        {"max_volume_ratio", phi.max_volume_ratio()},
                        {"lattice_mm", phi.lattice_mm()},
                        {"fitted_nodes", phi.fitted_nodes()},
                        {"harmonic_nodes", phi.harmonic_nodes()},
                        {"folds", phi.folds()}}},
                      {"particle_body_volume_change_pct", r.particle_body_volume_change_pct},
                      {"components", r.components},
                      {"skin_particles", r.skin_particles},
                      {"finite", r.finite}};
  if (r.global) {
    const fitting::GlobalStageReport& g = *r.global;
    const fitting::GlobalMap& map = g.map;
    const fitting::AffineFit& affine = map.affine;
    const Eigen::Vector3d& stretches = g.principal_stretches;
    j["global"] = {
        {"rms_before_mm", affine.rms_before_mm},
        {"rms_after_mm", map.rms_after_mm},
        {"iterations", affine.iterations},
        {"principal_stretches", {stretches.x(), stretches.y(), stretches.z()}},
        {"translation_mm", {affine.t.x(), affine.t.y(), affine.t.z()}},
        {"shear_coefficients_per_mm",
         std::vector<double>(map.shears.c.data(), map.shears.c.data() + map.shears.c.size())},
        {"shears_dropped", map.shears_dropped},
        {"shear_fields_sigma_mm", map.fields.empty() ? 0.0 : map.fields.sigma_mm},
        {"shears_largest_move_mm", g.moves.shears_mm},
        {"shear_fields_largest_move_mm", g.moves.fields_mm},
        {"flow_sigma_mm", map.flow.empty() ? 0.0 : map.flow.sigma_mm},
        {"flow_largest_move_mm", g.moves.flow_mm},
        {"found_by", map.found_by},
        {"kept_share", map.kept_share},
        {"organ_move_mm", g.organ_move_mm},
        {"shape_change_mm", g.shape_change_mm},
        {"equally_good_fits", g.equally_good_fits},
        {"equally_good_sd_mm", g.equally_good_sd_mm},
        {"posterior_sd_mm", g.posterior_sd_mm},
        {"posterior_max_sd_mm", g.posterior_max_sd_mm},
        {"refill_passes", g.refill_passes},
        {"particles_after_refill", g.particles_after_refill},
        {"volume_change_after_settling_pct", g.volume_change_after_settling_pct},
        {"wall_s", g.wall_s}};
  }
  return j;
}

FitStageOptions fit_stage_options_from(const config::Scene& scene) {
  FitStageOptions o;
  o.method = scene.text("fit", "method");
  o.measure_truth = scene.flag("fit", "measure_truth");
  if (o.method == "paper")
    o.paper = paper_fit_options_from(scene);
  else
    o.spread = spread_fit_options_from(scene);
  return o;
}

FitStageResult run_fit_stage(const FitStageOptions& options, ModelStageResult model,
                             const PointsStageResult& pts) {
  FitStageResult out;
  const std::string& method = options.method;
  const auto& points = pts.points;
  const double rho = model.model->radius_mm();
  const double truth_voxel = evaluation::kTruthVoxelMm;
  // The steps before the fit loop and after it (seconds each on a large organ), each shown
  // as one progress; between them the loop's, by its steps (its step budget, 20,000 by
  // default, is no measure of how far it has come).
  Progress preparing("fit: preparing", 6);
  std::optional<Progress> progress, finishing;
  fitting::FitObserver observer;
  observer.preparing = [&](int step, int, const std::string& done) {
    preparing.update(step, done);
    if (step == 6) {
      preparing.finish();
      progress.emplace("fit: steps", 0);
    }
  };
  observer.finishing = [&](int step, int steps, const std::string& done) {
    if (step == 0) {
      if (progress) progress->finish();
      finishing.emplace("fit: finishing", steps);
    } else if (finishing) {
      finishing->update(step, done);
    }
  };
  observer.row = [&](const fitting::HistoryRow& h) {
    throw_if_interrupted();
    if (progress) progress->update(h.step, fmt::format("residual {:.2f} mm", h.residual_mean_mm));
  };
  nlohmann::json summary = std::move(model.summary);
  fitting::FittedOrgan fitted;
  try {
    fitted = method == "paper"
                 ? fitting::fit_paper(std::move(model), points, options.paper, observer)
                 : fitting::fit_spread(std::move(model), points, options.spread, observer);
  } catch (const fitting::ModelBrokeError& e) {
    throw TargetNotMetError(std::string("fit: the model did not hold together: ") + e.what());
  } catch (const std::invalid_argument& e) {
    throw InputError(std::string("points: ") + e.what());
  }
  if (progress) progress->finish();
  if (finishing) finishing->finish();
  // What points that fit nothing usually are, said by both refusals below.
  constexpr const char* kCheckPoints =
      "check that they belong to this organ and are in the planning CT's patient coordinates, "
      "in mm";
  if (fitted.report.refused)
    throw TargetNotMetError(fmt::format(
        "fit: the points ask for an implausible change of the whole organ: their best fit moves "
        "it {:.1f} mm and stretches it {:.2f}x (the bounds: a move of {} mm, "
        "fit.spread.max_global_shift_mm; a stretch of {}x, fit.spread.max_global_stretch; a bend "
        "of {} of its size, fit.spread.global_max_shear); {}",
        fitted.report.refused_move_mm, fitted.report.refused_stretch,
        options.spread.global.max_shift_mm, options.spread.global.max_stretch,
        options.spread.global.max_shear_mm, kCheckPoints));
  // A fit that kept none of its points fitted nothing (not converged, its report says): no
  // result to write, refused before anything is.
  if (fitted.report.rejected_every_point())
    throw TargetNotMetError(fmt::format(
        "fit: all {} points were rejected as outliers (fit.{}.outlier_distance_mm): nothing was "
        "fitted; {}",
        fitted.report.points, fitted.report.method, kCheckPoints));
  if (fitted.report.local_stage_undone())  // the stop reason says why (tore or folded)
    spdlog::warn("fit: {}", fitted.report.fit.stop_reason);
  static_cast<fitting::OrganModel&>(out.model) = std::move(fitted.model);
  out.model.summary = std::move(summary);
  out.report = std::move(fitted.report);
  const fitting::FitReport& report = out.report;
  const fitting::EmbeddedBody& organ_before = *fitted.before;
  const fitting::EmbeddedBody& organ_after = *fitted.after;
  const particles::State& state = out.model.state;
  const double volume_voxel = report.volume_voxel_mm;
  const fitting::Deformation& phi = *report.deformation;
  out.deformation_folds = phi.folds();
  out.fit_summary = fit_summary(report);
  const UncertaintyOnSurface on_surface =
      uncertainty_on_surface(out.model.shape, phi, *report.uncertainty);
  out.fit_summary["uncertainty"] = on_surface.summary;
  if (pts.truth && options.measure_truth) {
    spdlog::info("fit: done in {} steps; measuring it against the known deformation ({} mm grid)",
                 report.fit.steps, truth_voxel);
    Stopwatch truth_clock;
    Progress truth_progress("truth", 4);
    // The organ as the model carried it before the fit, sampled once and compared with the
    // shape it was made from (the discretisation floor) and with the known deformed organ
    // (the undeformed error); the truth is sampled once for the three bodies compared with it.
    std::optional<evaluation::LatticeBody> before;
    geometry::SurfaceComparison floor;
    // A mask organ's model at rest is its shape: the same signed distance at the same levels
    // moved by the identity (fitting/embedded_body.h), voxel for voxel on any lattice, so
    // its floor is zero by construction and its shape is not sampled (on a 1.5 L liver,
    // 0.5 s of its truth's 3.2 s); the organ as it was is sampled on the truth's lattice.
    const geometry::Shape& shape_filled = out.model.shape;
    const bool rest_is_shape = shape_filled.mask &&
                               organ_before.shared_distance() == shape_filled.distance &&
                               organ_before.deformation().identity();
    if (!rest_is_shape) {  // the shape's lattice let go before the truth's is made
      const evaluation::KnownBody shape(evaluation::shape_body(shape_filled), shape_filled.extent(),
                                        truth_voxel);
      before = shape.sample(organ_before);
      floor = shape.compare(*before);
    }
    throw_if_interrupted();
    truth_progress.update(1, "the model before the fit against its shape");
    const evaluation::KnownBody truth(evaluation::deformed_body(pts.truth_shape, *pts.truth),
                                      deformed_bounds(pts.truth_shape, *pts.truth), truth_voxel);
    if (rest_is_shape) before = truth.sample(organ_before);  // floor: MSD 0
    const auto undeformed = truth.compare(*before);
    before.reset();
    throw_if_interrupted();
    truth_progress.update(2, "the organ left undeformed");
    const auto fitted_organ = truth.compare(organ_after);
    throw_if_interrupted();
    truth_progress.update(3, "the fitted organ");
    const auto fitted_balls = truth.compare(state.x, rho);
    truth_progress.update(4, "the fitted particles' balls");
    truth_progress.finish();
    const double denom = undeformed.msd_mm - floor.msd_mm;
    out.truth_summary = {
        {"msd_mm", fitted_organ.msd_mm},
        {"hd95_mm", fitted_organ.hd95_mm},
        {"dice", fitted_organ.dice},
        {"msd_undeformed_mm", undeformed.msd_mm},
        {"hd95_undeformed_mm", undeformed.hd95_mm},
        {"msd_floor_mm", floor.msd_mm},
        {"recovery", denom > 0 ? (undeformed.msd_mm - fitted_organ.msd_mm) / denom : 0.0},
        {"voxel_mm", truth_voxel},
        {"surface", "the reference moved with the particles (fitting/embedded_body.h)"},
        {"particle_balls",
         {{"msd_mm", fitted_balls.msd_mm},
          {"hd95_mm", fitted_balls.hd95_mm},
          {"dice", fitted_balls.dice}}}};
    // On the organ's own volume grid (rho/2, coarser for a large organ: at most about 8M
    // voxels), not the truth's 0.5 mm: a 2.3 L lung's true organ at 0.5 mm took 1.4 GB.
    out.truth_summary["uncertainty"] =
        uncertainty_coverage(on_surface, evaluation::deformed_body(pts.truth_shape, *pts.truth),
                             deformed_bounds(pts.truth_shape, *pts.truth), volume_voxel);
    out.truth_summary["uncertainty"]["voxel_mm"] = volume_voxel;
    out.truth_wall_s = truth_clock.elapsed_s();
    out.truth_summary["wall_s"] = out.truth_wall_s;
  }
  std::ostringstream csv;
  csv << "step,wall_s,residual_mean_mm,residual_max_mm,volume_change_pct,kinetic_energy_per_"
         "particle\n";
  for (const auto& h : report.fit.history) {
    csv << fmt::format("{},{:.6f},{:.6f},{:.6f},{},{:.6g}\n", h.step, h.wall_s, h.residual_mean_mm,
                       h.residual_max_mm,
                       std::isnan(h.volume_change_pct) ? std::string()
                                                       : fmt::format("{:.4f}", h.volume_change_pct),
                       h.kinetic_energy_per_particle);
  }
  out.history_csv = csv.str();
  if (!report.fit.converged) {
    std::vector<std::pair<double, int>> worst;
    for (size_t k = 0; k < report.fit.residuals_mm.size(); ++k)
      worst.push_back({report.fit.residuals_mm[k], static_cast<int>(k)});
    std::sort(worst.rbegin(), worst.rend());
    const double far_mm = report.residual_p95_tolerance_mm;
    // Which side of the fitted organ the points farther than the tolerance lie on: all
    // inside (or all outside) is what an organ smaller (or larger) than the planning one
    // leaves, since the fit keeps its volume.
    int far = 0, far_inside = 0;
    for (const auto& [r, k] : worst)
      if (r > far_mm) ++far, far_inside += organ_after.inside(points[static_cast<size_t>(k)].p_mm);
    std::string list;
    for (size_t w = 0; w < std::min<size_t>(5, worst.size()); ++w)
      list += fmt::format("{}#{} ({:.2f} mm)", w ? ", " : "", worst[w].second, worst[w].first);
    out.not_converged_message = fmt::format(
        "fit did not converge ({}): mean residual {:.2f} mm (tolerance {:.2f}), 95th percentile "
        "{:.2f} mm (tolerance {:.2f}: {} of {} points farther{}); worst: {}",
        report.fit.stop_reason, report.fit.residual_mean_mm, report.residual_tolerance_mm,
        report.fit.residual_p95_mm, far_mm, far, points.size(),
        far > 0 ? fmt::format(", {} of them inside the fitted organ", far_inside) : "", list);
  }
  if (out.deformation_folds)
    out.not_converged_message =
        (out.not_converged_message.empty() ? "" : out.not_converged_message + "; ") +
        "the fitted deformation folds (det(grad phi) <= 0 near the organ): nothing is exported";
  return out;
}

std::vector<std::string> fit_warnings(const FitStageResult& fit) {
  std::vector<std::string> w;
  const double organ_change = fit.fit_summary["volume_change_pct"].get<double>();
  const double balls_change = fit.fit_summary["particle_body_volume_change_pct"].get<double>();
  const double tolerance = fit.report.volume_tolerance_pct;
  if (std::abs(organ_change) > tolerance)
    w.push_back(
        std::abs(balls_change) <= tolerance && std::abs(organ_change) > 3.0
            ? fmt::format(
                  "fit: the organ's volume changed by {:+.1f}% while the particles' own body "
                  "changed by {:+.1f}%: the particles rearranged under a deformation larger than "
                  "the global map explains, and the organ they carry is not to be trusted there",
                  organ_change, balls_change)
            : fmt::format("fit: the organ's volume changed by {:+.1f}%", organ_change));
  if (fit.report.global && fit.report.global->map.shears_dropped)
    w.push_back(
        "fit: the points asked for an implausible bend (fit.spread.max_global_stretch and "
        "fit.spread.global_max_shear bound it); the global stage used a stretch and shift only");
  if (fit.fit_summary["rejected_points"].get<int>() > 0) {
    w.push_back(fmt::format("fit: {} points rejected as outliers",
                            fit.fit_summary["rejected_points"].get<int>()));
  }
  return w;
}

}  // namespace organfit::pipeline
