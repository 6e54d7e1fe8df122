#include "organfit/fitting/global_map_posterior.h"

#include <Eigen/Dense>
#include <array>
#include <cmath>
#include <map>

#include "global_solvers.h"
#include "organfit/geometry/sample_grid.h"

namespace organfit::fitting {

GlobalMapPosterior global_map_posterior(const GlobalMap& map, const SurfaceSamples& surface,
                                        const std::vector<AttractivePoint>& points, double noise_mm,
                                        double motion_sd_mm, double local_sd_mm,
                                        double local_length_mm, double mads) {
  using Vec12 = Eigen::Matrix<double, 12, 1>;
  using Mat12 = Eigen::Matrix<double, 12, 12>;
  const Eigen::Index n = surface.points.cols();
  GlobalMapPosterior out;
  out.variance_mm2 = Eigen::VectorXd::Zero(n);
  if (n == 0) return out;
  const Eigen::Vector3d c = surface.points.rowwise().mean();
  const double radius = std::sqrt((surface.points.colwise() - c).colwise().squaredNorm().mean());
  // The unknowns in the prior's units: dtheta = sd .* u, u ~ N(0, I) a priori.
  Vec12 sd;
  sd.head<3>().setConstant(motion_sd_mm);
  sd.tail<9>().setConstant(motion_sd_mm / std::max(radius, 1e-9));
  const Eigen::Matrix3d normal_map = map.affine.a.inverse().transpose();
  Eigen::Matrix3Xd& mapped = out.at_mm;
  mapped.resize(3, n);
  std::vector<Vec12> g(static_cast<size_t>(n));
#pragma omp parallel for schedule(static)
  for (Eigen::Index j = 0; j < n; ++j) {
    const Eigen::Vector3d x = surface.points.col(j);
    mapped.col(j) = map.apply(x);
    const Eigen::Vector3d nu = (normal_map * surface.normals.col(j)).normalized();
    Vec12 gj;
    gj.head<3>() = nu;
    for (int i = 0; i < 3; ++i)
      gj.segment<3>(3 + 3 * i) = nu(i) * (x - c);
    g[static_cast<size_t>(j)] = gj.cwiseProduct(sd);
  }
  // The points' information. Each point observes g(x_p)^T dtheta plus the local change there
  // (the uncertainty's GP: s^2 exp(-d^2 / 2 l^2), surface_uncertainty.h) plus its noise:
  // F = G^T (K + N)^-1 G. Points within a cell of l/2 or more (at most 400 cells, a solve of
  // 400^3) are one observation at their mean, noise n^2 over their weight; with cells wider
  // than l/2 their mean local change is taken as one point's (s^2), which tells less than
  // the points do: a wider posterior, never a narrower one.
  Mat12 information = Mat12::Zero();
  if (!points.empty()) {
    const geometry::SampleGrid grid(mapped, geometry::SampleGrid::surface_cell_mm(mapped));
    std::vector<int> nearest(points.size());
    std::vector<double> r(points.size()), w;
    for (size_t k = 0; k < points.size(); ++k) {
      const auto [j, d2] = grid.nearest(points[k].p_mm);
      nearest[k] = j;
      r[k] = std::sqrt(d2);
    }
    detail::robust_weights(r, points, mads, w);
    struct Cell {
      Eigen::Vector3d at = Eigen::Vector3d::Zero();
      Vec12 g = Vec12::Zero();
      double weight = 0;
    };
    std::map<std::array<long long, 3>, Cell> cells;
    for (double cell_mm = 0.5 * local_length_mm;; cell_mm *= 1.26) {
      cells.clear();
      for (size_t k = 0; k < points.size(); ++k) {
        if (!(w[k] > 0)) continue;
        const Eigen::Vector3d& p = points[k].p_mm;
        Cell& cell = cells[{static_cast<long long>(std::floor(p.x() / cell_mm)),
                            static_cast<long long>(std::floor(p.y() / cell_mm)),
                            static_cast<long long>(std::floor(p.z() / cell_mm))}];
        cell.at += w[k] * p;
        cell.g += w[k] * g[static_cast<size_t>(nearest[k])];
        cell.weight += w[k];
      }
      if (cells.size() <= 400) break;
    }
    const auto count = static_cast<Eigen::Index>(cells.size());
    Eigen::MatrixXd obs(count, 12), cov(count, count);
    std::vector<Eigen::Vector3d> at;
    Eigen::Index row = 0;
    for (const auto& [key, cell] : cells) {
      obs.row(row) = (cell.g / cell.weight).transpose();
      at.push_back(cell.at / cell.weight);
      cov(row, row) = noise_mm * noise_mm / cell.weight;
      ++row;
    }
    const double s2 = local_sd_mm * local_sd_mm, l2 = local_length_mm * local_length_mm;
    for (Eigen::Index a = 0; a < count; ++a)
      for (Eigen::Index b = 0; b <= a; ++b) {
        const double k = s2 * std::exp(-(at[a] - at[b]).squaredNorm() / (2 * l2));
        if (a == b)
          cov(a, a) += k;
        else
          cov(a, b) = cov(b, a) = k;
      }
    information = obs.transpose() * cov.llt().solve(obs);
  }
  // det A = 1, linearised: tr(A^-1 dA) = sum_il (A^-1)_li dA_il = 0; in u, that normal
  // scaled by sd. Z: an orthonormal basis of the plane it is normal to.
  const Eigen::Matrix3d b = map.affine.a.inverse();
  Vec12 normal = Vec12::Zero();
  for (int i = 0; i < 3; ++i)
    for (int l = 0; l < 3; ++l)
      normal(3 + 3 * i + l) = b(l, i);
  normal = normal.cwiseProduct(sd).normalized();
  const Eigen::HouseholderQR<Vec12> qr(normal);
  const Mat12 q = qr.householderQ() * Mat12::Identity();
  const Eigen::Matrix<double, 12, 11> z = q.rightCols<11>();
  const Eigen::Matrix<double, 11, 11> precision =
      z.transpose() * (information + Mat12::Identity()) * z;
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix<double, 11, 11>> eigen(precision);
  const Eigen::Matrix<double, 12, 11> root =
      z * eigen.eigenvectors() * eigen.eigenvalues().cwiseInverse().cwiseSqrt().asDiagonal();
#pragma omp parallel for schedule(static)
  for (Eigen::Index j = 0; j < n; ++j)
    out.variance_mm2(j) = (root.transpose() * g[static_cast<size_t>(j)]).squaredNorm();
  return out;
}

}  // namespace organfit::fitting
