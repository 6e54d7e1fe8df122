#pragma once
// The fit loop: integrate the model under the data forces until the points are reached
// and the model has settled, or progress stalls, or a budget runs out.
#include <functional>
#include <limits>
#include <string>
#include <vector>

#include "organfit/fitting/attractive_points.h"
#include "organfit/particles/integrator.h"

namespace organfit::fitting {

/// Data residual of each point (mm): distance from the point to the model surface, the
/// balls' (| min over skin particles of |p - x_i| - rho |) or, given `feet`, the organ's
/// embedded surface (the tangent plane at the nearest foot: nearest_surface_particle).
/// Rejected points (outliers) get NaN and are left out of the statistics.
std::vector<double> data_residuals(const std::vector<AttractivePoint>& points,
                                   const particles::Positions& x, const std::vector<int>& skin,
                                   double radius_mm,
                                   const std::vector<PointStatus>* status = nullptr,
                                   const SurfaceFeet* feet = nullptr);

/// Mean, largest and 95th percentile (nearest rank) of the residuals (mm), NaNs (rejected
/// points) left out; zeros when none is left.
struct ResidualSummary {
  double mean_mm = 0, max_mm = 0, p95_mm = 0;
};
ResidualSummary summarise_residuals(const std::vector<double>& residuals_mm);

struct FitOptions {
  double residual_mean_tolerance_mm = 0.5;  ///< converged: mean residual at most this
  double residual_max_tolerance_mm = 0.0;   ///< ... and the 95th percentile at most this (0: the
                                            ///< particle radius): one noisy point does not decide
  double kinetic_tolerance = 1e-4;          ///< ... and kinetic energy per particle below this
  long long max_steps = 20000;
  double max_wall_s = 60.0;
  int record_every = 20;            ///< steps between history rows; once the points are
                                    ///< explained, a row also comes at the first step the
                                    ///< kinetic energy is within tolerance
  int stall_rows = 25;              ///< stop when the mean residual has not improved by
  double stall_improvement = 0.01;  ///< this fraction over that many rows
  /// Volume of the model (mm^3) for the history; empty: not recorded.
  std::function<double(const particles::Positions&)> volume;
  int volume_every_rows = 5;
  /// volume() of the state passed in, when the caller has it (0: measured here). The
  /// first row is that state too: its change is 0 without measuring it again.
  double volume_at_start_mm3 = 0;
  /// The organ's surface as each particle sees it, for the residuals; empty: the balls'
  /// (see data_residuals).
  SurfaceFeet surface_feet;
};

struct HistoryRow {
  long long step = 0;
  double wall_s = 0;
  double residual_mean_mm = 0, residual_max_mm = 0, residual_p95_mm = 0;
  double volume_change_pct = 0;  ///< NaN when not measured at this row
  double kinetic_energy_per_particle = 0;
};

struct FitResult {
  bool converged = false;
  std::string stop_reason;  ///< "converged", "stalled", "step budget", "wall-time budget"
  long long steps = 0;
  double wall_s = 0;  ///< fitting work
  /// of wall_s, the dynamics steps alone (forces, skin, data forces): the set-up (the first
  /// neighbour lists and forces) and the rows' residuals left out
  double steps_wall_s = 0;
  double instrument_wall_s = 0;  ///< history measurements (volume), not part of the fit
  double residual_mean_mm = 0, residual_max_mm = 0, residual_p95_mm = 0;
  /// The step of the first row that explained the points (see run_fit); -1: none did.
  long long explained_at_step = -1;
  std::vector<double> residuals_mm;
  std::vector<HistoryRow> history;
  /// volume() of the state as it ends when the last row measured it (the fit stops right
  /// after a row), else NaN.
  double volume_at_end_mm3 = std::numeric_limits<double>::quiet_NaN();
};

/// Runs the fit. `data_term` must already be in `model`; `skin_of` returns the current
/// skin particles (for residuals). `on_row` (optional) sees each history row.
/// `while_reaching` (optional) may adjust the state or force terms between rows until the
/// points are explained (a row after the first with the mean and 95th percentile within
/// tolerance), and not after: e.g. the skeleton's rest shape follows the fit while the
/// surface is on its way, then stays, so that the body settles elastically about the shape
/// that explained the points instead of creeping on after their noise (the discrepancy
/// principle: a fit taken beyond the noise's level fits the noise). Forces are recomputed
/// after it.
FitResult run_fit(
    particles::Model& model, particles::State& state,
    const particles::IntegratorOptions& integrator_options,
    const std::vector<AttractivePoint>& points,
    const std::function<const std::vector<int>&(const particles::Positions&)>& skin_of,
    const std::vector<PointStatus>* status, const FitOptions& options,
    const std::function<void(const HistoryRow&)>& on_row = nullptr,
    const std::function<void(particles::State&)>& while_reaching = nullptr);

}  // namespace organfit::fitting
