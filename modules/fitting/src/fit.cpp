#include "organfit/fitting/fit.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>
#include <numeric>

namespace organfit::fitting {

std::vector<double> data_residuals(const std::vector<AttractivePoint>& points,
                                   const particles::Positions& x, const std::vector<int>& skin,
                                   double radius_mm, const std::vector<PointStatus>* status,
                                   const SurfaceFeet* feet) {
  std::vector<double> out(points.size(), std::numeric_limits<double>::infinity());
  const SkinIndex index(x, skin, feet);
#pragma omp parallel for schedule(dynamic, 64)
  for (long long k = 0; k < static_cast<long long>(points.size()); ++k) {
    const auto at = static_cast<size_t>(k);
    if (status && at < status->size() && (*status)[at].rejected) {
      out[at] = std::numeric_limits<double>::quiet_NaN();
      continue;
    }
    const double gap = index.nearest_surface_particle(points[at].p_mm, radius_mm).second;
    if (std::isfinite(gap)) out[at] = std::abs(gap);
  }
  return out;
}

ResidualSummary summarise_residuals(const std::vector<double>& residuals_mm) {
  ResidualSummary out;
  double sum = 0;
  std::vector<double> kept;
  for (double v : residuals_mm)
    if (!std::isnan(v)) sum += v, out.max_mm = std::max(out.max_mm, v), kept.push_back(v);
  if (kept.empty()) return out;
  out.mean_mm = sum / static_cast<double>(kept.size());
  const size_t k = static_cast<size_t>(std::ceil(0.95 * static_cast<double>(kept.size()))) - 1;
  std::nth_element(kept.begin(), kept.begin() + static_cast<long>(k), kept.end());
  out.p95_mm = kept[k];
  return out;
}

FitResult run_fit(
    particles::Model& model, particles::State& state,
    const particles::IntegratorOptions& integrator_options,
    const std::vector<AttractivePoint>& points,
    const std::function<const std::vector<int>&(const particles::Positions&)>& skin_of,
    const std::vector<PointStatus>* status, const FitOptions& o,
    const std::function<void(const HistoryRow&)>& on_row,
    const std::function<void(particles::State&)>& while_reaching) {
  using Clock = std::chrono::steady_clock;
  const auto start = Clock::now();
  double instrument_s = 0;
  auto now_s = [&] {
    return std::chrono::duration<double>(Clock::now() - start).count() - instrument_s;
  };

  FitResult result;
  const double rho = model.radius_mm();
  const double max_tol = o.residual_max_tolerance_mm > 0 ? o.residual_max_tolerance_mm : rho;
  const int n = std::max(1, state.size());
  particles::Integrator integ(model, integrator_options);
  integ.refresh_forces(state);
  double v0 = 0;
  if (o.volume) {
    const auto t0 = Clock::now();
    v0 = o.volume_at_start_mm3 > 0 ? o.volume_at_start_mm3 : o.volume(state.x);
    instrument_s += std::chrono::duration<double>(Clock::now() - t0).count();
  }
  double best_mean = std::numeric_limits<double>::infinity();
  int rows_since_best = 0;
  for (int row = 0;; ++row) {
    HistoryRow h;
    h.step = integ.stats().steps;
    const std::vector<double> r =
        data_residuals(points, state.x, skin_of(state.x), rho, status, &o.surface_feet);
    const ResidualSummary summary = summarise_residuals(r);
    h.residual_mean_mm = summary.mean_mm;
    h.residual_max_mm = summary.max_mm;
    h.residual_p95_mm = summary.p95_mm;
    h.kinetic_energy_per_particle = integ.kinetic_energy(state) / n;
    h.volume_change_pct = std::numeric_limits<double>::quiet_NaN();
    result.volume_at_end_mm3 = std::numeric_limits<double>::quiet_NaN();
    if (o.volume && row % std::max(1, o.volume_every_rows) == 0) {
      const auto t0 = Clock::now();
      result.volume_at_end_mm3 = row == 0 ? v0 : o.volume(state.x);  // row 0: the start
      h.volume_change_pct = 100.0 * (result.volume_at_end_mm3 - v0) / v0;
      instrument_s += std::chrono::duration<double>(Clock::now() - t0).count();
    }
    h.wall_s = now_s();
    result.history.push_back(h);
    if (on_row) on_row(h);
    result.residuals_mm = r;
    result.residual_mean_mm = h.residual_mean_mm;
    result.residual_max_mm = h.residual_max_mm;
    result.residual_p95_mm = h.residual_p95_mm;

    // The 95th percentile, not the largest: one noisy point must not decide convergence.
    const bool explained = h.residual_mean_mm <= o.residual_mean_tolerance_mm &&
                           h.residual_p95_mm <= max_tol && row > 0;
    if (explained && result.explained_at_step < 0) result.explained_at_step = h.step;
    if (explained && h.kinetic_energy_per_particle <= o.kinetic_tolerance) {
      result.converged = true;
      result.stop_reason = "converged";
      break;
    }
    if (h.residual_mean_mm < best_mean * (1 - o.stall_improvement)) {
      best_mean = h.residual_mean_mm;
      rows_since_best = 0;
    } else if (++rows_since_best >= o.stall_rows) {
      result.stop_reason = "stalled";
      break;
    }
    if (integ.stats().steps >= o.max_steps) {
      result.stop_reason = "step budget";
      break;
    }
    if (h.wall_s >= o.max_wall_s) {
      result.stop_reason = "wall-time budget";
      break;
    }
    if (while_reaching && result.explained_at_step < 0) {
      while_reaching(state);
      integ.refresh_forces(state);
    }
    const auto steps_start = Clock::now();
    // Explained but still moving: the row comes as soon as the body is at rest, not at the
    // end of a full row's steps.
    const auto moving = [&](long long) {
      return !explained || integ.kinetic_energy(state) / n > o.kinetic_tolerance;
    };
    integ.run(state, std::min<long long>(o.record_every, o.max_steps - integ.stats().steps),
              moving);
    result.steps_wall_s += std::chrono::duration<double>(Clock::now() - steps_start).count();
  }
  result.steps = integ.stats().steps;
  result.wall_s = now_s();
  result.instrument_wall_s = instrument_s;
  return result;
}

}  // namespace organfit::fitting
