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
// fit has no information there.
// What each point observes is the fit's residual there, y_i (mm, signed along the fitted
// surface's normal): about 0 +- n where the fit explains the points, more where it does
// not (a fit that stalled, or noise beyond the stated). The posterior mean of the error,
//   m(x) = k_x^T (K + n^2 I)^-1 y,
// is where the points say the true surface is; the fitted surface is not moved there, so
// the spread reported is the root mean square of the error about the fitted surface,
// sqrt(m^2 + sigma^2): where the fit explains its points, m is their noise smoothed and
// small, and where it left them 2 mm off, the surface is not claimed to within n.
// The model's own resolution r is added in quadrature: the particles carry the surface only
// to their own scale, an error no number of points averages away (without it, 200
// noise-free points put sigma under 0.4 mm on a cube whose particles round its edges by
// more). So sd_mm(x) = sqrt(m(x)^2 + sigma^2(x) + r^2).
// The prior's scale may also depend on the place: s(x)^2 = s^2 + u(x)^2, u given at sample
// places (the value at the one nearest x), and k(a, b) = s(a) s(b) exp(-|a - b|^2 / (2 l^2)),
// a covariance for any s(.) >= 0: how far the surface may be off where no point is differs
// from place to place (where the global maps the points cannot tell apart disagree).
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
  /// Up to this many points, sigma is the posterior given all of them (one solve of
  /// max_points^3). With more, the points of each cell of l/2 become one observation at
  /// their mean (position and residual) with noise n / sqrt(count), and sigma at x is the
  /// posterior given the `local_observations` of them nearest x within 3 l (beyond, a
  /// point's covariance is under 1.2% of the prior's): a posterior given part of the data,
  /// its variance never narrower than given all of it, at a cost a query that no point
  /// count raises.
  int max_points = 400;
  int local_observations = 64;
};

/// u(x)^2 of the prior's s(x)^2 = s^2 + u(x)^2 (mm^2) at sample places (mm); between them, the
/// value at the nearest place. Empty: u = 0 everywhere.
struct PriorVarianceField {
  Eigen::Matrix3Xd at_mm;
  Eigen::VectorXd variance_mm2;
};

class SurfaceUncertainty {
 public:
  /// `residuals_mm`: the fit's residual y_i at each point (mm, signed along the fitted
  /// surface's outward normal: the point outside is positive); empty: all 0. `extra`: u^2.
  /// Throws std::invalid_argument when an option is not positive and finite, when residuals
  /// are given and their count is not the points' or one is not finite, or when `extra`'s
  /// places and values differ in count or a value is negative or not finite.
  SurfaceUncertainty(const std::vector<Eigen::Vector3d>& points_mm,
                     const SurfaceUncertaintyOptions& options,
                     const std::vector<double>& residuals_mm = {}, PriorVarianceField extra = {});
  /// sqrt(m(x)^2 + sigma^2(x) + r^2), mm: with residuals within the noise between about
  /// hypot(n, r) (at a point) and hypot(s(x), r) (far from every point).
  double sd_mm(const Eigen::Vector3d& x_mm) const;
  /// The value where no point informs it, at the place where the prior is widest (mm):
  /// hypot(s, max u, r).
  double far_sd_mm() const;
  /// s(x), the prior's scale at x (mm).
  double prior_sd_mm(const Eigen::Vector3d& x_mm) const;
  /// Distance from x to the nearest point (mm; infinity without points).
  double nearest_point_mm(const Eigen::Vector3d& x_mm) const;
  const SurfaceUncertaintyOptions& options() const { return options_; }
  /// The points as given (mm), one per column.
  const Eigen::Matrix3Xd& points_mm() const { return all_points_; }
  /// The residuals as given (empty: all 0), one per point.
  const std::vector<double>& residuals_mm() const { return residuals_mm_; }
  /// u^2 as given.
  const PriorVarianceField& prior_variance_field() const { return extra_; }
  /// The points' bounding box (empty box without points).
  geometry::Aabb points_box() const;

 private:
  SurfaceUncertaintyOptions options_;
  Eigen::Matrix3Xd points_;           ///< the observations (binned when there are many)
  Eigen::Matrix3Xd all_points_;       ///< the points as given (nearest_point_mm, points_box)
  std::vector<double> residuals_mm_;  ///< as given
  std::shared_ptr<const geometry::SampleGrid> nearest_;  ///< over all_points_
  PriorVarianceField extra_;
  std::shared_ptr<const geometry::SampleGrid> extra_places_;  ///< over extra_.at_mm
  Eigen::VectorXd scale_;                                     ///< s(.) at the observations (mm)
  Eigen::VectorXd y_;                                         ///< the observations' residuals (mm)
  Eigen::VectorXd noise2_;  ///< the observations' noise variances (mm^2)
  bool local_ = false;      ///< binned: each query conditions on its nearest observations
  std::shared_ptr<const geometry::SampleGrid> observations_;  ///< over points_, when local_
  // All observations at once (not local_):
  Eigen::MatrixXd lower_;    ///< Cholesky factor of K + N
  Eigen::VectorXd weights_;  ///< (K + N)^-1 y: m(x) = k_x^T weights_
  /// k(a, b) = s(a) s(b) exp(-|a - b|^2 / (2 l^2)) (mm^2), with s(a) = s_a, s(b) = s_b.
  double covariance(double s_a, const Eigen::Vector3d& a, double s_b,
                    const Eigen::Vector3d& b) const;
  /// K + N over the observations `of` (indices into points_; all when empty).
  Eigen::MatrixXd observed_covariance(const std::vector<int>& of) const;
  /// The posterior given the observations `of` (indices into points_; all when empty and
  /// not local_): sqrt(m^2 + sigma^2 + r^2).
  double posterior_sd_mm(const Eigen::Vector3d& x_mm, const std::vector<int>& of) const;
};

}  // namespace organfit::fitting
