#include "organfit/evaluation/baselines.h"

#include <Eigen/Cholesky>
#include <Eigen/LU>
#include <Eigen/SVD>
#include <cmath>
#include <limits>
#include <memory>

namespace organfit::evaluation {

PointMap similarity_icp(const Eigen::Matrix3Xd& surface, const Eigen::Matrix3Xd& points,
                        int iterations) {
  Eigen::Matrix3d r = Eigen::Matrix3d::Identity();
  Eigen::Vector3d t = Eigen::Vector3d::Zero();
  double s = 1;
  const Eigen::Index n = points.cols(), m = surface.cols();
  for (int it = 0; it < iterations && n >= 3; ++it) {
    // Pairs: each point with its closest moved surface sample.
    Eigen::Matrix3Xd src(3, n);
    for (Eigen::Index i = 0; i < n; ++i) {
      double best = std::numeric_limits<double>::infinity();
      Eigen::Index at = 0;
      for (Eigen::Index j = 0; j < m; ++j) {
        const double d = (s * r * surface.col(j) + t - points.col(i)).squaredNorm();
        if (d < best) best = d, at = j;
      }
      src.col(i) = surface.col(at);
    }
    // Umeyama (1991): the similarity taking src to the points.
    const Eigen::Vector3d ms = src.rowwise().mean(), mp = points.rowwise().mean();
    const Eigen::Matrix3Xd a = src.colwise() - ms, b = points.colwise() - mp;
    const Eigen::Matrix3d cov = b * a.transpose() / static_cast<double>(n);
    Eigen::JacobiSVD<Eigen::Matrix3d> svd(cov, Eigen::ComputeFullU | Eigen::ComputeFullV);
    Eigen::Matrix3d d = Eigen::Matrix3d::Identity();
    if ((svd.matrixU() * svd.matrixV().transpose()).determinant() < 0) d(2, 2) = -1;
    r = svd.matrixU() * d * svd.matrixV().transpose();
    const double var = a.squaredNorm() / static_cast<double>(n);
    s = var > 0 ? (svd.singularValues().asDiagonal() * d).trace() / var : 1.0;
    t = mp - s * r * ms;
  }
  return [r, t, s](const Eigen::Vector3d& x) -> Eigen::Vector3d { return s * r * x + t; };
}

PointMap coherent_point_drift(const Eigen::Matrix3Xd& surface, const Eigen::Matrix3Xd& points,
                              const CpdOptions& o) {
  const Eigen::Index m = surface.cols(), n = points.cols();
  // Both sets in the surface's frame brought to zero mean and unit scale, so that beta and
  // lambda mean the same for any organ size. (Myronenko's code normalises each set by its
  // own mean and scale; with points on half the surface that moves and shrinks the organ.)
  const Eigen::Vector3d my = surface.rowwise().mean();
  const double sy = std::sqrt((surface.colwise() - my).squaredNorm() / static_cast<double>(m));
  const Eigen::Vector3d mx = my;
  const double sx = sy;
  const Eigen::MatrixXd y = ((surface.colwise() - my) / sy).transpose(),
                        x = ((points.colwise() - mx) / sx).transpose();
  const double two_b2 = 2 * o.beta * o.beta;
  Eigen::MatrixXd g(m, m);
  for (Eigen::Index i = 0; i < m; ++i)
    for (Eigen::Index j = 0; j < m; ++j)
      g(i, j) = std::exp(-(y.row(i) - y.row(j)).squaredNorm() / two_b2);
  Eigen::MatrixXd w = Eigen::MatrixXd::Zero(m, 3);
  Eigen::MatrixXd ty = y;
  double sigma2 = 0;
  for (Eigen::Index i = 0; i < m; ++i)
    for (Eigen::Index j = 0; j < n; ++j)
      sigma2 += (x.row(j) - y.row(i)).squaredNorm();
  sigma2 /= 3.0 * static_cast<double>(m * n);
  for (int it = 0; it < o.iterations && sigma2 > 1e-10; ++it) {
    // E step: posteriors P (M x N) with the uniform outlier term.
    Eigen::MatrixXd p(m, n);
    const double c = std::pow(2 * M_PI * sigma2, 1.5) * o.w / (1 - o.w) * static_cast<double>(m) /
                     static_cast<double>(n);
    for (Eigen::Index j = 0; j < n; ++j) {
      double sum = 0;
      for (Eigen::Index i = 0; i < m; ++i)
        sum += p(i, j) = std::exp(-(x.row(j) - ty.row(i)).squaredNorm() / (2 * sigma2));
      p.col(j) /= (sum + c);
    }
    const Eigen::VectorXd p1 = p.rowwise().sum(), pt1 = p.colwise().sum().transpose();
    const double np = p1.sum();
    if (!(np > 1e-12)) break;
    // M step: (G + lambda sigma^2 d(P1)^-1) W = d(P1)^-1 P X - Y.
    Eigen::MatrixXd a = g;
    for (Eigen::Index i = 0; i < m; ++i)
      a(i, i) += o.lambda * sigma2 / std::max(p1(i), 1e-12);
    Eigen::MatrixXd rhs = p * x;
    for (Eigen::Index i = 0; i < m; ++i)
      rhs.row(i) = rhs.row(i) / std::max(p1(i), 1e-12) - y.row(i);
    w = a.partialPivLu().solve(rhs);
    ty = y + g * w;
    const double previous = sigma2;
    double num = 0;
    for (Eigen::Index j = 0; j < n; ++j)
      num += pt1(j) * x.row(j).squaredNorm();
    num -= 2 * (p * x).cwiseProduct(ty).sum();
    for (Eigen::Index i = 0; i < m; ++i)
      num += p1(i) * ty.row(i).squaredNorm();
    sigma2 = std::max(num / (3 * np), 1e-8);
    if (std::abs(previous - sigma2) < 1e-8 * previous) break;
  }
  auto centres = std::make_shared<const Eigen::MatrixXd>(y);
  auto weights = std::make_shared<const Eigen::MatrixXd>(w);
  return [centres, weights, two_b2, my, sy, mx, sx](const Eigen::Vector3d& z) -> Eigen::Vector3d {
    const Eigen::Vector3d zn = (z - my) / sy;
    Eigen::Vector3d out = zn;
    for (Eigen::Index i = 0; i < centres->rows(); ++i)
      out += std::exp(-(centres->row(i).transpose() - zn).squaredNorm() / two_b2) *
             weights->row(i).transpose();
    return mx + sx * out;
  };
}

}  // namespace organfit::evaluation
