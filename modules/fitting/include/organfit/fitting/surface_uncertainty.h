#pragma once
// Where the true surface may lie, given the attractive points: the posterior standard
// deviation (mm) of a Gaussian process on the fitted surface's normal error.
//
// The error e(x) (true surface minus fitted, along the normal) has the prior
//   e ~ GP(0, k),  k(a, b) = s^2 exp(-|a - b|^2 / (2 l^2)),
// and each attractive point p_i observes it with noise n: the fit leaves a residual
// there no larger than the noise. The posterior variance at x is
//   sigma^2(x) = s^2 - k_x^T (K + n^2 I)^-1 k_x,   K_ij = k(p_i, p_j),  (k_x)_i = k(x, p_i),
// so sigma is about n at the points, and rises to s beyond a few l from every point: the
// fit has no information there. The posterior mean is not used (the fit already passes
// through the points); only where the points leave the surface free is said.
// The model's own resolution r is added in quadrature, sigma^2(x) + r^2: the particles
// carry the surface only to their own scale, an error no number of points averages away
// (without it, 200 noise-free points put sigma under 0.4 mm on a cube whose particles
// round its edges by more).
#include <Eigen/Core>
#include <memory>
#include <vector>

#include "organfit/geometry/image_geometry.h"
#include "organfit/geometry/sample_grid.h"

namespace organfit::fitting {

struct SurfaceUncertaintyOptions {
  double prior_sd_mm = 2.0;       ///< s: how far the surface may be off where no point is
  double length_mm = 10.0;        ///< l: the distance over which one point informs the surface
  double noise_sd_mm = 0.5;       ///< n: the points' noise
  double resolution_sd_mm = 0.0;  ///< r: the model's own resolution (>= 0)
  /// More points than this are binned first: the points of a cell (l/2 wide, wider when
  /// needed) become one observation at their mean with noise n / sqrt(count), which
  /// keeps the solve O(max_points^3) whatever the point count.
  int max_points = 400;
};

class SurfaceUncertainty {
 public:
  /// Throws std::invalid_argument when an option is not positive and finite.
  SurfaceUncertainty(const std::vector<Eigen::Vector3d>& points_mm,
                     const SurfaceUncertaintyOptions& options);
  /// sigma(x), mm: between about hypot(n, r) (at a point) and hypot(s, r) (far from every
  /// point).
  double sd_mm(const Eigen::Vector3d& x_mm) const;
  /// sigma where no point informs it (mm): hypot(s, r), the largest sd_mm gives.
  double far_sd_mm() const;
  /// Distance from x to the nearest point (mm; infinity without points).
  double nearest_point_mm(const Eigen::Vector3d& x_mm) const;
  const SurfaceUncertaintyOptions& options() const { return options_; }
  /// The points' bounding box (empty box without points).
  geometry::Aabb points_box() const;

 private:
  SurfaceUncertaintyOptions options_;
  Eigen::Matrix3Xd points_;      ///< the observations (binned when there are many)
  Eigen::Matrix3Xd all_points_;  ///< the points as given (nearest_point_mm, points_box)
  std::shared_ptr<const geometry::SampleGrid> nearest_;  ///< over all_points_
  Eigen::MatrixXd lower_;                                ///< Cholesky factor of K + n^2 I
};

}  // namespace organfit::fitting
