#pragma once
// The points stage (generate on a known deformation, or read a file) and the fit stage.
#include <filesystem>
#include <functional>
#include <nlohmann/json.hpp>
#include <optional>

#include "organfit/config/scene.h"
#include "organfit/evaluation/synthetic.h"
#include "organfit/fitting/fit.h"
#include "organfit/fitting/global_fit.h"
#include "organfit/fitting/surface_uncertainty.h"
#include "organfit/pipeline/model_stage.h"
#include "organfit/pipeline/points_file.h"

namespace organfit::pipeline {

struct PointsStageResult {
  std::vector<fitting::AttractivePoint> points;
  std::optional<evaluation::Deformation> truth;  ///< set when the points were generated
  evaluation::Shape truth_shape;                 ///< the shape they were sampled on
  PointsCt declared_ct;                          ///< the CT a points file declares
  nlohmann::json summary;
};

/// A point set by extension: a table (read_points_table, with the CT it declares), or the
/// vertices of a .ply, .vtk or .vtp. Throws InputError naming the file on bad content or
/// no points.
PointsTable read_points_file(const std::filesystem::path& file);

PointsStageResult run_points_stage(const config::Scene& scene, const ModelStageResult& model);

/// The true deformation the points section describes (evaluation::Deformation), about the
/// shape's centre.
evaluation::Deformation deformation_from(const config::Scene& scene,
                                         const evaluation::Shape& shape);

/// A box holding the deformed shape: its corners mapped, widened by the non-affine parts.
geometry::Aabb deformed_bounds(const evaluation::Shape& shape,
                               const evaluation::Deformation& deformation);

struct FitStageResult {
  fitting::FitResult fit;
  nlohmann::json fit_summary;    ///< run.json "fit"
  nlohmann::json truth_summary;  ///< run.json "truth" (when the truth is known)
  std::string history_csv;
  std::string not_converged_message;  ///< which points are left and how far
  /// The fitted deformation folds (det(grad phi) <= 0 somewhere): the run exits 3 and
  /// exports nothing, since a folded map puts one point of tissue in two places.
  bool deformation_folds = false;
  /// The fitted deformation (what the export and the report show the organ through).
  std::shared_ptr<const fitting::Deformation> deformation;
  /// Where the true surface may lie given the points (run.json fit.uncertainty).
  std::shared_ptr<const fitting::SurfaceUncertainty> uncertainty;
  /// How the organ's reference body follows the particles (fitting/embedded_body.h):
  /// the global map (identity for the paper's method) and where the particles were
  /// placed before the local stage.
  fitting::GlobalMap global_map;
  particles::Positions placed;
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
UncertaintyOnSurface uncertainty_on_surface(const evaluation::Shape& planning,
                                            const fitting::Deformation& phi,
                                            const fitting::SurfaceUncertainty& u);

/// Its calibration against a known truth: the share of the samples whose distance to the
/// true surface (its inside rasterised at `voxel_mm` over `truth_bounds`) is at most 2
/// sigma; all, seen half, unseen half.
nlohmann::json uncertainty_coverage(const UncertaintyOnSurface& on_surface,
                                    const std::function<bool(const Eigen::Vector3d&)>& truth_inside,
                                    const geometry::Aabb& truth_bounds, double voxel_mm);

FitStageResult run_fit_stage(const config::Scene& scene, ModelStageResult& model,
                             const PointsStageResult& points);

}  // namespace organfit::pipeline
