#pragma once
// The fit stage: the model fitted to the attractive points by the scene's method (the
// paper's, or ours: a global map, then the local stage), with the measures run.json
// reports, the uncertainty, and the truth when the points were made on a known one.
#include <filesystem>
#include <functional>
#include <nlohmann/json.hpp>
#include <optional>

#include "organfit/config/scene.h"
#include "organfit/evaluation/synthetic.h"
#include "organfit/fitting/fit.h"
#include "organfit/fitting/global_fit.h"
#include "organfit/fitting/organ_fit.h"
#include "organfit/fitting/surface_uncertainty.h"
#include "organfit/pipeline/model_stage.h"
#include "organfit/pipeline/points_stage.h"

namespace organfit::pipeline {

struct FitStageResult {
  ModelStageResult model;        ///< the fitted model
  fitting::FitReport report;     ///< the fit's own account (fitting/organ_fit.h)
  nlohmann::json fit_summary;    ///< run.json "fit"
  nlohmann::json truth_summary;  ///< run.json "truth" (when the truth is known)
  std::string history_csv;
  std::string not_converged_message;  ///< which points are left and how far
  /// The fitted deformation folds (det(grad phi) <= 0 somewhere): the run exits 3 and
  /// exports nothing, since a folded map puts one point of tissue in two places.
  bool deformation_folds = false;
  double truth_wall_s = 0;  ///< measuring against the known truth (not part of the update)
};

/// The fit's uncertainty on the fitted surface: 4,000 samples of the planning surface
/// carried by phi, sigma at each, split at the median distance to the nearest point into
/// the half the points saw and the half they did not; `summary` is run.json's
/// fit.uncertainty (prior, length, noise; median and 95th percentile of sigma, all, seen,
/// unseen).
struct UncertaintyOnSurface {
  std::vector<Eigen::Vector3d> surface;
  std::vector<double> sigma, nearest;
  double split_mm = 0;
  nlohmann::json summary;
  bool unseen(size_t i) const { return nearest[i] > split_mm; }
};
UncertaintyOnSurface uncertainty_on_surface(const geometry::Shape& planning,
                                            const fitting::Deformation& phi,
                                            const fitting::SurfaceUncertainty& u);

/// Its calibration against a known truth: the share of the samples whose distance to the
/// true surface (its inside sampled at `voxel_mm` over `truth_bounds`,
/// evaluation::sample_inside) is at most 2 sigma; all, seen half, unseen half.
nlohmann::json uncertainty_coverage(const UncertaintyOnSurface& on_surface,
                                    const evaluation::InsideTest& truth,
                                    const geometry::Aabb& truth_bounds, double voxel_mm);

/// The scene's fit settings for both methods, and for each.
fitting::OrganFitOptions organ_fit_options_from(const config::Scene& scene);
fitting::PaperFitOptions paper_fit_options_from(const config::Scene& scene);
fitting::SpreadFitOptions spread_fit_options_from(const config::Scene& scene);

/// run.json's "fit" (without its "uncertainty", which the stage adds).
nlohmann::json fit_summary(const fitting::FitReport& report);

/// The fit stage's settings: the method and its options, and whether to measure the truth.
struct FitStageOptions {
  std::string method = "spread";     ///< fit.method: "paper" or "spread"
  fitting::PaperFitOptions paper;    ///< used when method is "paper"
  fitting::SpreadFitOptions spread;  ///< used when method is "spread"
  bool measure_truth = true;         ///< fit.measure_truth: against the points' known deformation
};
FitStageOptions fit_stage_options_from(const config::Scene& scene);

/// Fits `model` (moved in) to the points by options.method, measures the truth when the
/// points were made on a known one (options.measure_truth), and returns the fitted model.
/// Throws InputError on bad points and TargetNotMetError when the points ask for an
/// implausible change of the whole organ or the model does not hold together.
FitStageResult run_fit_stage(const FitStageOptions& options, ModelStageResult model,
                             const PointsStageResult& points);

/// What a user must be told of a fit that ran: the organ's volume changed by more than 1%
/// (and whether the particles' own body did), shears dropped, points rejected.
std::vector<std::string> fit_warnings(const FitStageResult& fit);

}  // namespace organfit::pipeline
