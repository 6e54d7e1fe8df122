#pragma once
// The fit of an organ model to attractive points (METHOD.md s.3 and s.4), as library
// calls: no scene, file, log or known truth inside.
//   fit_paper   the paper's method: each point pulls the skin particles within its
//               influence radius (PaperAttractiveForce, eq. 5-7) until the residuals
//               settle;
//   fit_spread  ours: a volume-preserving map of the whole organ fitted to the points
//               (global_fit.h), the body re-filled in its mapped shape and settled, the
//               skeleton rebuilt on it, then smooth local patches (SpreadAttractiveForce)
//               with the skeleton's rest shape following the fit until the points are
//               explained; a local stage that tears the organ into pieces, folds it, or
//               changes its volume by more than fit.volume_tolerance_pct is undone (the
//               global stage's organ, which keeps the volume, is kept).
// Both take the model by value (move it in, or pass copy_model(m) to keep m) and return
// it fitted, with the organ it carries before and after and what run.json's `fit` says.
#include <Eigen/Core>
#include <functional>
#include <memory>
#include <optional>
#include <stdexcept>
#include <string>
#include <vector>

#include "organfit/fitting/attractive_points.h"
#include "organfit/fitting/fit.h"
#include "organfit/fitting/global_fit.h"
#include "organfit/fitting/organ_model.h"
#include "organfit/fitting/spread_force.h"
#include "organfit/fitting/surface_uncertainty.h"

namespace organfit::fitting {

/// The fit loop's settings, either method's (the scene's `fit` section; these defaults are
/// the scene's, pipeline/scene_schema.cpp declares the keys from them).
struct OrganFitOptions {
  double damping_ratio = 0.5;  ///< of critical damping, during the fit
  double skin_voxel_r0 = 0.5;  ///< voxel of the skin detector (r0; 0.5 r0 = rho)
  /// On the mean residual (mm), beside the model's own residual floor (in quadrature).
  double residual_tolerance_mm = 0.5;
  /// On the 95th percentile (mm; 0: p95_tolerance_mm of the radius and the mean's).
  double residual_max_tolerance_mm = 0.0;
  double kinetic_tolerance = 1e-4;  ///< kinetic energy per particle at rest (E0)
  long long max_steps = 20000;
  double max_wall_s = 60.0;
  int record_every = 20;  ///< steps between history rows
  /// The prior standard deviation (mm) of the local change where no point is, for the
  /// fit's uncertainty (surface_uncertainty.h).
  double unseen_change_sd_mm = 1.7;
  /// The prior standard deviation (mm) of the organ's move since planning where the points
  /// do not tell it (the global map's affine part, global_map_posterior.h), likewise.
  double unseen_motion_sd_mm = 4.0;
  /// The organ's volume change (%, either way) a fit may make: beyond it the spread fit's
  /// local stage is undone, and a run warns of either method's.
  double volume_tolerance_pct = 1.0;
};

struct PaperFitOptions {
  OrganFitOptions fit;
  PaperForceParams force;
};

struct SpreadFitOptions {
  OrganFitOptions fit;
  /// The global stage's map. Its noise_mm is not read: the points' noise is what the fit
  /// accepts, fit.residual_tolerance_mm.
  AffineFitOptions global;
  SpreadForceParams local;  ///< the local stage's patches
};

/// What a long fit tells its caller while it runs; each may be empty.
struct FitObserver {
  /// Step `step` of the `steps` before the fit loop is done (the organ's volume, the
  /// residual floor, the global map, the re-fill, the skeleton, the surface feet).
  std::function<void(int step, int steps, const std::string& done)> preparing;
  /// Each history row of the fit loop; may throw to stop the fit (an interrupt).
  std::function<void(const HistoryRow&)> row;
  /// Step `step` of the `steps` after the fit loop is done (0: the loop itself; then the
  /// pieces, the deformation phi, the organ's volume, the uncertainty).
  std::function<void(int step, int steps, const std::string& done)> finishing;
};

/// The global stage of fit_spread.
struct GlobalStageReport {
  GlobalMap map;
  Eigen::Vector3d principal_stretches = Eigen::Vector3d::Ones();  ///< singular values of a
  LargestMoves moves;          ///< largest moves of the shears and fields (mm)
  double shape_change_mm = 0;  ///< shape_change_mm(map, surface)
  double organ_move_mm = 0;    ///< the map's move of the organ: its surface's mean move (mm)
  /// The fits the points could not tell from the map (fit_global_map's equally_good, the map
  /// included), and the RMS over the surface and over them of their distance from the map's
  /// surface along its normal (mm): how far the points leave the organ's place undecided.
  int equally_good_fits = 1;
  double equally_good_sd_mm = 0;
  /// The affine part's posterior (global_map_posterior.h): the surface's standard deviation
  /// from it along its normal, RMS over the surface and largest (mm).
  double posterior_sd_mm = 0, posterior_max_sd_mm = 0;
  int refill_passes = 0;  ///< re-fills until the settled volume matched
  int particles_after_refill = 0;
  double volume_change_after_settling_pct = 0;
  double wall_s = 0;
};

struct FitReport {
  std::string method;  ///< "paper" or "spread"
  FitResult fit;       ///< the fit loop (wall_s includes the global stage)
  /// fit_spread: the points asked for a change of the whole organ beyond the plausible
  /// (global_fit.h, GlobalMap::refused): nothing was fitted, the model is as it came; with
  /// the best fit's move of the organ (mm) and largest stretch.
  bool refused = false;
  double refused_move_mm = 0, refused_stretch = 1;
  int points = 0, rejected_points = 0;
  /// Every point rejected as an outlier: nothing was fitted, whatever the loop said.
  bool rejected_every_point() const { return points > 0 && rejected_points == points; }
  /// The particles' pieces at planning (an organ in parts is filled in parts) and after the
  /// local stage: more than at planning, the local stage tore the organ; it was undone.
  int planning_pieces = 1, pieces = 1;
  bool local_stage_folded = false;  ///< the local stage folded the organ; it was undone
  /// The local stage changed the organ's volume by more than volume_tolerance_pct; undone.
  bool local_stage_changed_volume = false;
  bool local_stage_undone() const {
    return pieces > planning_pieces || local_stage_folded || local_stage_changed_volume;
  }
  double volume_tolerance_pct = 1.0;     ///< the options' (fit_warnings reads it)
  double residual_floor_mm = 0;          ///< a point on the model's own surface, on average
  double residual_tolerance_mm = 0;      ///< on the mean: the stated one and the floor
  double residual_p95_tolerance_mm = 0;  ///< on the 95th percentile
  /// The organ's volume (mm^3) before and after, counted on a grid of volume_voxel_mm;
  /// and after/before from the deformation's Jacobian over it (the grid's error cancels).
  double volume_voxel_mm = 0, volume_before_mm3 = 0, volume_after_mm3 = 0, volume_ratio = 1;
  double particle_body_volume_change_pct = 0;  ///< the balls' own body (closed by rho)
  int components = 0;                          ///< of the particles after the fit
  size_t skin_particles = 0;
  bool finite = true;                                     ///< every position finite
  std::optional<GlobalStageReport> global;                ///< fit_spread
  std::shared_ptr<const Deformation> deformation;         ///< phi, planning to today
  std::shared_ptr<const SurfaceUncertainty> uncertainty;  ///< where the surface may lie
};

/// The model after the fit, the organ it carried before and carries now, the report.
struct FittedOrgan {
  OrganModel model;
  std::optional<EmbeddedBody> before, after;  ///< unset when refused
  FitReport report;
};

/// The model did not hold together (particles flung apart): no organ to carry.
class ModelBrokeError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

/// The fits. Throw std::invalid_argument on bad points (fitting::validate_points),
/// ModelBrokeError when the fitted particles no longer make one organ, and
/// particles::StabilityError when the simulation cannot continue stably.
FittedOrgan fit_paper(OrganModel model, const std::vector<AttractivePoint>& points,
                      const PaperFitOptions& options, const FitObserver& observer = {});
FittedOrgan fit_spread(OrganModel model, const std::vector<AttractivePoint>& points,
                       const SpreadFitOptions& options, const FitObserver& observer = {});

/// The fit's default tolerance on the residuals' 95th percentile (mm): the particle radius
/// rho, or the 95th percentile that residuals of mean `mean_tolerance_mm` have when they
/// are a noise's (half-normal: 2.46 times the mean), whichever is larger. Below the latter
/// the criterion asks more than points of the accepted noise can give: a model of 0.75 mm
/// particles fitted to 10,000 points of 0.5 mm noise stopped at its wall-time budget with
/// 8.6% of them beyond rho and its mean residual at its floor since the first row.
double p95_tolerance_mm(double rho_mm, double mean_tolerance_mm);

}  // namespace organfit::fitting
