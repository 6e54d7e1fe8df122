#pragma once
// What a user would otherwise pick to fit an organ surface to sparse points, for the
// side-by-side evaluation (bench fit). Each fits the model's surface samples (M x 3) to
// the points (N x 3) and returns a map that moves any point, so that every method's
// result is the model's own particles moved by it, measured by the same metrics.
#include <Eigen/Core>
#include <functional>

namespace organfit::evaluation {

using PointMap = std::function<Eigen::Vector3d(const Eigen::Vector3d&)>;

/// Rigid plus isotropic scale ICP: closest surface sample to each point, then Umeyama's
/// similarity (rotation R, scale s, translation t) from the pairs; `iterations` rounds.
/// Map: x -> s R x + t.
PointMap similarity_icp(const Eigen::Matrix3Xd& surface, const Eigen::Matrix3Xd& points,
                        int iterations = 30);

/// Non-rigid coherent point drift, Myronenko and Song (2010), Fig. 4: the surface
/// samples Y are the GMM centroids moved by T(Y) = Y + G W, G_ij = exp(-|y_i - y_j|^2 /
/// (2 beta^2)); EM with outlier weight w, regularisation lambda, sigma^2 updated each
/// step; `iterations` rounds or until sigma^2 changes by < 1e-8 relative. Both sets are
/// first moved and scaled by the surface's mean and scale (beta and lambda are in those
/// units, the authors' defaults 2 and 3). Map: x -> x + sum_j exp(-|x - y_j|^2 /
/// (2 beta^2)) W_j in that frame.
struct CpdOptions {
  double w = 0.1;       ///< outlier weight in [0, 1)
  double beta = 2.0;    ///< kernel width (normalised units)
  double lambda = 3.0;  ///< smoothness
  int iterations = 150;
};
PointMap coherent_point_drift(const Eigen::Matrix3Xd& surface, const Eigen::Matrix3Xd& points,
                              const CpdOptions& options);

}  // namespace organfit::evaluation
