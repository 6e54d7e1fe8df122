#include "organfit/fitting/surface_uncertainty.h"

#include <Eigen/Cholesky>
#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <map>
#include <stdexcept>

namespace organfit::fitting {

SurfaceUncertainty::SurfaceUncertainty(const std::vector<Eigen::Vector3d>& points_mm,
                                       const SurfaceUncertaintyOptions& options,
                                       const std::vector<double>& residuals_mm,
                                       PriorVarianceField extra)
    : options_(options),
      all_points_(3, static_cast<Eigen::Index>(points_mm.size())),
      residuals_mm_(residuals_mm),
      extra_(std::move(extra)) {
  for (double v : {options.prior_sd_mm, options.length_mm, options.noise_sd_mm})
    if (!(v > 0) || !std::isfinite(v))
      throw std::invalid_argument("SurfaceUncertainty: s, l and n must be positive and finite");
  if (!(options.resolution_sd_mm >= 0) || !std::isfinite(options.resolution_sd_mm))
    throw std::invalid_argument("SurfaceUncertainty: r must be >= 0 and finite");
  if (options.max_points < 1 || options.local_observations < 1)
    throw std::invalid_argument(
        "SurfaceUncertainty: max_points and local_observations must be at least 1");
  if (!residuals_mm.empty() && residuals_mm.size() != points_mm.size())
    throw std::invalid_argument("SurfaceUncertainty: one residual per point");
  for (double y : residuals_mm)
    if (!std::isfinite(y)) throw std::invalid_argument("SurfaceUncertainty: residual not finite");
  if (extra_.at_mm.cols() != extra_.variance_mm2.size() || !extra_.at_mm.allFinite() ||
      !extra_.variance_mm2.allFinite() || (extra_.variance_mm2.array() < 0).any())
    throw std::invalid_argument(
        "SurfaceUncertainty: the prior's variance field needs one finite value >= 0 a place");
  if (extra_.at_mm.cols() > 0)
    extra_places_ = std::make_shared<const geometry::SampleGrid>(extra_.at_mm);
  for (size_t i = 0; i < points_mm.size(); ++i)
    all_points_.col(static_cast<Eigen::Index>(i)) = points_mm[i];
  nearest_ = std::make_shared<const geometry::SampleGrid>(all_points_);
  // The observations: the points themselves, or their means (positions and residuals)
  // over cells of l/2.
  std::vector<double> counts(points_mm.size(), 1.0);
  points_ = all_points_;
  y_ = Eigen::VectorXd::Zero(static_cast<Eigen::Index>(points_mm.size()));
  for (size_t i = 0; i < residuals_mm.size(); ++i)
    y_[static_cast<Eigen::Index>(i)] = residuals_mm[i];
  local_ = points_.cols() > options.max_points;
  if (local_) {
    const double cell = options.length_mm / 2;
    struct Bin {
      Eigen::Vector3d sum_mm = Eigen::Vector3d::Zero();
      double residual_sum_mm = 0, count = 0;
    };
    std::map<std::array<long long, 3>, Bin> bins;
    for (size_t i = 0; i < points_mm.size(); ++i) {
      const Eigen::Vector3d& p = points_mm[i];
      const std::array<long long, 3> key{static_cast<long long>(std::floor(p.x() / cell)),
                                         static_cast<long long>(std::floor(p.y() / cell)),
                                         static_cast<long long>(std::floor(p.z() / cell))};
      Bin& b = bins[key];
      b.sum_mm += p, b.count += 1;
      if (!residuals_mm.empty()) b.residual_sum_mm += residuals_mm[i];
    }
    points_.resize(3, static_cast<Eigen::Index>(bins.size()));
    y_.resize(static_cast<Eigen::Index>(bins.size()));
    counts.clear();
    Eigen::Index c = 0;
    for (const auto& [key, b] : bins) {
      points_.col(c) = b.sum_mm / b.count, y_[c] = b.residual_sum_mm / b.count;
      counts.push_back(b.count), ++c;
    }
    observations_ = std::make_shared<const geometry::SampleGrid>(points_);
  }
  noise2_.resize(points_.cols());
  scale_.resize(points_.cols());
  for (Eigen::Index i = 0; i < points_.cols(); ++i) {
    noise2_[i] = options.noise_sd_mm * options.noise_sd_mm / counts[static_cast<size_t>(i)];
    scale_[i] = prior_sd_mm(points_.col(i));
  }
  if (local_) return;
  const Eigen::LLT<Eigen::MatrixXd> llt(observed_covariance({}));  // positive definite
  lower_ = llt.matrixL();
  weights_ = llt.solve(y_);
}

double SurfaceUncertainty::covariance(double s_a, const Eigen::Vector3d& a, double s_b,
                                      const Eigen::Vector3d& b) const {
  const double inv_2l2 = 1.0 / (2 * options_.length_mm * options_.length_mm);
  return s_a * s_b * std::exp(-(a - b).squaredNorm() * inv_2l2);
}

Eigen::MatrixXd SurfaceUncertainty::observed_covariance(const std::vector<int>& of) const {
  auto at = [&of](Eigen::Index i) { return of.empty() ? i : of[static_cast<size_t>(i)]; };
  const Eigen::Index m = of.empty() ? points_.cols() : static_cast<Eigen::Index>(of.size());
  Eigen::MatrixXd k(m, m);
  for (Eigen::Index i = 0; i < m; ++i) {
    for (Eigen::Index j = 0; j <= i; ++j)
      k(i, j) = k(j, i) =
          covariance(scale_[at(i)], points_.col(at(i)), scale_[at(j)], points_.col(at(j)));
    k(i, i) += noise2_[at(i)];
  }
  return k;
}

double SurfaceUncertainty::sd_mm(const Eigen::Vector3d& x) const {
  if (points_.cols() == 0) return std::hypot(prior_sd_mm(x), options_.resolution_sd_mm);
  if (!local_) return posterior_sd_mm(x, {});
  // The nearest local_observations within 3 l.
  std::vector<int> near;
  observations_->within(x, 3 * options_.length_mm, near);
  const auto keep = static_cast<size_t>(options_.local_observations);
  if (near.size() > keep) {
    auto closer = [&](int a, int b) {
      const double da = (points_.col(a) - x).squaredNorm(), db = (points_.col(b) - x).squaredNorm();
      return da < db || (da == db && a < b);
    };
    std::nth_element(near.begin(), near.begin() + static_cast<long>(keep), near.end(), closer);
    near.resize(keep);
  }
  if (near.empty()) return std::hypot(prior_sd_mm(x), options_.resolution_sd_mm);
  return posterior_sd_mm(x, near);
}

double SurfaceUncertainty::prior_sd_mm(const Eigen::Vector3d& x) const {
  const double s = options_.prior_sd_mm;
  if (!extra_places_) return s;
  return std::sqrt(s * s + extra_.variance_mm2[extra_places_->nearest(x).first]);
}

double SurfaceUncertainty::posterior_sd_mm(const Eigen::Vector3d& x,
                                           const std::vector<int>& of) const {
  const double sx = prior_sd_mm(x), s2 = sx * sx;
  const double r2 = options_.resolution_sd_mm * options_.resolution_sd_mm;
  auto at = [&of](Eigen::Index i) { return of.empty() ? i : of[static_cast<size_t>(i)]; };
  const Eigen::Index m = of.empty() ? points_.cols() : static_cast<Eigen::Index>(of.size());
  Eigen::VectorXd kx(m);
  for (Eigen::Index i = 0; i < m; ++i)
    kx[i] = covariance(sx, x, scale_[at(i)], points_.col(at(i)));
  double mean = 0, explained = 0;
  if (of.empty()) {
    // k_x^T (L L^T)^-1 k_x = |L^-1 k_x|^2
    explained = lower_.triangularView<Eigen::Lower>().solve(kx).squaredNorm();
    mean = kx.dot(weights_);
  } else {
    Eigen::VectorXd y(m);
    for (Eigen::Index i = 0; i < m; ++i)
      y[i] = y_[at(i)];
    const Eigen::LLT<Eigen::MatrixXd> llt(observed_covariance(of));
    explained = llt.matrixL().solve(kx).squaredNorm();
    mean = kx.dot(llt.solve(y));
  }
  return std::sqrt(mean * mean + std::max(0.0, s2 - explained) + r2);
}

double SurfaceUncertainty::far_sd_mm() const {
  const double widest = extra_.variance_mm2.size() > 0 ? extra_.variance_mm2.maxCoeff() : 0.0;
  return std::hypot(std::sqrt(options_.prior_sd_mm * options_.prior_sd_mm + widest),
                    options_.resolution_sd_mm);
}

geometry::Aabb SurfaceUncertainty::points_box() const {
  geometry::Aabb box;
  if (all_points_.cols() == 0) return box;
  box.min_mm = all_points_.rowwise().minCoeff();
  box.max_mm = all_points_.rowwise().maxCoeff();
  return box;
}

double SurfaceUncertainty::nearest_point_mm(const Eigen::Vector3d& x) const {
  if (all_points_.cols() == 0) return std::numeric_limits<double>::infinity();
  return std::sqrt(nearest_->nearest(x).second);
}

}  // namespace organfit::fitting
