#include "organfit/fitting/surface_uncertainty.h"

#include <Eigen/Cholesky>
#include <array>
#include <cmath>
#include <limits>
#include <map>
#include <stdexcept>

namespace organfit::fitting {

SurfaceUncertainty::SurfaceUncertainty(const std::vector<Eigen::Vector3d>& points_mm,
                                       const SurfaceUncertaintyOptions& options)
    : options_(options), all_points_(3, static_cast<Eigen::Index>(points_mm.size())) {
  for (double v : {options.prior_sd_mm, options.length_mm, options.noise_sd_mm})
    if (!(v > 0) || !std::isfinite(v))
      throw std::invalid_argument("SurfaceUncertainty: s, l and n must be positive and finite");
  if (!(options.resolution_sd_mm >= 0) || !std::isfinite(options.resolution_sd_mm))
    throw std::invalid_argument("SurfaceUncertainty: r must be >= 0 and finite");
  if (options.max_points < 1)
    throw std::invalid_argument("SurfaceUncertainty: max_points must be at least 1");
  for (size_t i = 0; i < points_mm.size(); ++i)
    all_points_.col(static_cast<Eigen::Index>(i)) = points_mm[i];
  nearest_ = std::make_shared<const geometry::SampleGrid>(all_points_);
  // The observations: the points themselves, or their means over cells of a grid.
  std::vector<double> counts(points_mm.size(), 1.0);
  points_ = all_points_;
  for (double cell = options.length_mm / 2; points_.cols() > options.max_points; cell *= 1.5) {
    std::map<std::array<long long, 3>, std::pair<Eigen::Vector3d, double>> bins;
    for (const auto& p : points_mm) {
      const std::array<long long, 3> key{static_cast<long long>(std::floor(p.x() / cell)),
                                         static_cast<long long>(std::floor(p.y() / cell)),
                                         static_cast<long long>(std::floor(p.z() / cell))};
      auto& b = bins.try_emplace(key, Eigen::Vector3d::Zero(), 0.0).first->second;
      b.first += p, b.second += 1;
    }
    points_.resize(3, static_cast<Eigen::Index>(bins.size()));
    counts.clear();
    Eigen::Index c = 0;
    for (const auto& [key, b] : bins)
      points_.col(c++) = b.first / b.second, counts.push_back(b.second);
  }
  const Eigen::Index m = points_.cols();
  const double s2 = options.prior_sd_mm * options.prior_sd_mm;
  const double inv_2l2 = 1.0 / (2 * options.length_mm * options.length_mm);
  Eigen::MatrixXd k(m, m);
  for (Eigen::Index i = 0; i < m; ++i)
    for (Eigen::Index j = 0; j <= i; ++j)
      k(i, j) = k(j, i) = s2 * std::exp(-(points_.col(i) - points_.col(j)).squaredNorm() * inv_2l2);
  for (Eigen::Index i = 0; i < m; ++i)
    k(i, i) += options.noise_sd_mm * options.noise_sd_mm / counts[static_cast<size_t>(i)];
  lower_ = Eigen::LLT<Eigen::MatrixXd>(k).matrixL();  // K + N is positive definite
}

double SurfaceUncertainty::sd_mm(const Eigen::Vector3d& x) const {
  const double s2 = options_.prior_sd_mm * options_.prior_sd_mm;
  const double inv_2l2 = 1.0 / (2 * options_.length_mm * options_.length_mm);
  if (points_.cols() == 0) return far_sd_mm();
  const double r2 = options_.resolution_sd_mm * options_.resolution_sd_mm;
  Eigen::VectorXd kx(points_.cols());
  for (Eigen::Index i = 0; i < points_.cols(); ++i)
    kx[i] = s2 * std::exp(-(points_.col(i) - x).squaredNorm() * inv_2l2);
  // k_x^T (L L^T)^-1 k_x = |L^-1 k_x|^2
  const Eigen::VectorXd v = lower_.triangularView<Eigen::Lower>().solve(kx);
  return std::sqrt(std::max(0.0, s2 - v.squaredNorm()) + r2);
}

double SurfaceUncertainty::far_sd_mm() const {
  return std::hypot(options_.prior_sd_mm, options_.resolution_sd_mm);
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
