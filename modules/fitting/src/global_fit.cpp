#include "organfit/fitting/global_fit.h"

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <limits>
#include <numeric>

#include "organfit/geometry/mask_ops.h"
#include "organfit/particles/lattice_fill.h"

namespace organfit::fitting {

SurfaceSamples surface_samples(const particles::Positions& x, const std::vector<int>& skin,
                               double radius_mm) {
  const double r0 = 2 * radius_mm;
  const double reach2 = (1.6 * r0) * (1.6 * r0);
  SurfaceSamples out;
  out.points.resize(3, static_cast<Eigen::Index>(skin.size()));
  out.normals.resize(3, static_cast<Eigen::Index>(skin.size()));
  const Eigen::Vector3d body_centre = x.rowwise().mean();
  for (size_t s = 0; s < skin.size(); ++s) {
    const int i = skin[s];
    Eigen::Vector3d sum = Eigen::Vector3d::Zero();
    int count = 0;
    for (int j = 0; j < x.cols(); ++j) {
      if (j != i && (x.col(j) - x.col(i)).squaredNorm() < reach2) sum += x.col(j), ++count;
    }
    Eigen::Vector3d n = count > 0 ? Eigen::Vector3d(x.col(i) - sum / count) : Eigen::Vector3d::Zero();
    if (n.norm() < 1e-6 * r0) n = x.col(i) - body_centre;  // flat spot: point away from the centre
    n.normalize();
    out.normals.col(static_cast<Eigen::Index>(s)) = n;
    out.points.col(static_cast<Eigen::Index>(s)) = x.col(i) + radius_mm * n;
  }
  return out;
}

AffineFit fit_volume_preserving_affine(const SurfaceSamples& surface,
                                       const std::vector<AttractivePoint>& points,
                                       const AffineFitOptions& o) {
  AffineFit fit;
  const int m = static_cast<int>(points.size());
  if (m < 4 || surface.points.cols() == 0) return fit;
  Eigen::Matrix3Xd p(3, m);
  for (int k = 0; k < m; ++k) p.col(k) = points[k].p_mm;
  const Eigen::Vector3d pc = p.rowwise().mean();
  const double spread2 = (p.colwise() - pc).squaredNorm() / m;
  const double lambda = o.regularisation * spread2 * m;

  std::vector<int> match(m);
  std::vector<double> r(m), w(m);
  auto correspond = [&](const Eigen::Matrix3d& a, const Eigen::Vector3d& t) {
    const Eigen::Matrix3Xd moved = (a * surface.points).colwise() + t;
    for (int k = 0; k < m; ++k) {
      Eigen::Index j;
      r[k] = std::sqrt((moved.colwise() - p.col(k)).colwise().squaredNorm().minCoeff(&j));
      match[k] = static_cast<int>(j);
    }
    // Outliers: beyond median + outlier_mads * 1.4826 MAD get no weight.
    std::vector<double> sorted = r;
    std::nth_element(sorted.begin(), sorted.begin() + m / 2, sorted.end());
    const double median = sorted[m / 2];
    for (double& v : sorted) v = std::abs(v - median);
    std::nth_element(sorted.begin(), sorted.begin() + m / 2, sorted.end());
    const double cut = median + o.outlier_mads * 1.4826 * std::max(sorted[m / 2], 1e-6);
    double sum = 0;
    int kept = 0;
    for (int k = 0; k < m; ++k) {
      w[k] = r[k] <= cut ? points[k].confidence : 0.0;
      if (w[k] > 0) sum += r[k] * r[k], ++kept;
    }
    return std::sqrt(sum / std::max(1, kept));
  };
  fit.rms_before_mm = correspond(fit.a, fit.t);
  double previous = fit.rms_before_mm;
  for (int it = 0; it < o.iterations; ++it) {
    // Unknowns theta = [a row 0, a row 1, a row 2, t] (12). Point-to-plane rows
    // n^T (a s + t) = n^T p with n the matched normal mapped by a^-T; point-to-point rows
    // (a s + t)_r = p_r with weight mu; a pull lambda |a - I|^2.
    const Eigen::Matrix3d normal_map = fit.a.inverse().transpose();
    Eigen::Matrix<double, 12, 12> nrm = Eigen::Matrix<double, 12, 12>::Zero();
    Eigen::Matrix<double, 12, 1> rhs = Eigen::Matrix<double, 12, 1>::Zero();
    for (int k = 0; k < m; ++k) {
      if (w[k] == 0) continue;
      const Eigen::Vector3d s = surface.points.col(match[k]);
      const Eigen::Vector3d n = (normal_map * surface.normals.col(match[k])).normalized();
      Eigen::Matrix<double, 12, 1> row;
      row << n.x() * s, n.y() * s, n.z() * s, n;
      nrm += w[k] * row * row.transpose();
      rhs += w[k] * row * n.dot(p.col(k));
      for (int c = 0; c < 3; ++c) {
        Eigen::Matrix<double, 12, 1> pp = Eigen::Matrix<double, 12, 1>::Zero();
        pp.segment<3>(3 * c) = s;
        pp(9 + c) = 1.0;
        nrm += o.point_to_point * w[k] * pp * pp.transpose();
        rhs += o.point_to_point * w[k] * pp * p(c, k);
      }
    }
    for (int c = 0; c < 3; ++c) {
      for (int d = 0; d < 3; ++d) nrm(3 * c + d, 3 * c + d) += lambda;
      rhs(3 * c + c) += lambda;
    }
    const Eigen::Matrix<double, 12, 1> theta = nrm.ldlt().solve(rhs);
    Eigen::Matrix3d a;
    a << theta.segment<3>(0).transpose(), theta.segment<3>(3).transpose(), theta.segment<3>(6).transpose();
    Eigen::Vector3d t = theta.segment<3>(9);
    const double det = a.determinant();
    if (!(det > 0) || !a.allFinite() || !t.allFinite()) break;  // degenerate: keep the last good map
    // det(a) = 1, scaling about the matched surface's centroid so the fit stays in place.
    const double scale = 1.0 / std::cbrt(det);
    Eigen::Vector3d centroid = Eigen::Vector3d::Zero();
    double wsum = 0;
    for (int k = 0; k < m; ++k) centroid += w[k] * surface.points.col(match[k]), wsum += w[k];
    centroid /= std::max(wsum, 1e-12);
    const Eigen::Vector3d image = a * centroid + t;
    a *= scale;
    t = image - a * centroid;
    const double rms = correspond(a, t);
    fit.a = a;
    fit.t = t;
    fit.iterations = it + 1;
    fit.rms_after_mm = rms;
    if (it >= 10 && std::abs(previous - rms) < 1e-5 * (1 + previous)) break;
    previous = rms;
  }
  if (fit.iterations == 0) fit.rms_after_mm = fit.rms_before_mm;
  return fit;
}

Eigen::Vector3d GlobalMap::inverse(const Eigen::Vector3d& q) const {
  return affine.a.inverse() * (q - affine.t);
}

particles::Positions refill_mapped_body(const particles::Positions& x, double radius_mm,
                                        double a_nn_mm, const GlobalMap& map) {
  const int n = static_cast<int>(x.cols());
  if (n == 0) return x;
  // Depth inside the current body (balls closed), on a grid of rho/2.
  const double voxel = 0.5 * radius_mm;
  const geometry::Aabb box{x.rowwise().minCoeff(), x.rowwise().maxCoeff()};
  const geometry::ImageGeometry g = geometry::grid_covering(box, voxel, 2 * radius_mm + 2 * voxel);
  geometry::LabelVolume body = geometry::rasterize_balls(x, radius_mm, g);
  geometry::close_mask(body, radius_mm);
  std::vector<std::uint8_t> outside(body.labels.size());
  for (size_t i = 0; i < outside.size(); ++i) outside[i] = body.labels[i] == 0;
  const std::vector<double> depth2 = geometry::squared_distance_transform(outside, g);
  auto depth_at = [&](const Eigen::Vector3d& q) {
    const Eigen::Vector3d idx = g.physical_to_index(q);
    const int i = static_cast<int>(std::lround(idx.x())), j = static_cast<int>(std::lround(idx.y())),
              k = static_cast<int>(std::lround(idx.z()));
    if (i < 0 || j < 0 || k < 0 || i >= g.size[0] || j >= g.size[1] || k >= g.size[2]) return 0.0;
    return std::sqrt(depth2[g.linear_index(i, j, k)]);
  };
  // Candidate sites: the lattice over the mapped box, centred on the mapped centroid.
  geometry::Aabb mapped{Eigen::Vector3d::Constant(std::numeric_limits<double>::infinity()),
                        Eigen::Vector3d::Constant(-std::numeric_limits<double>::infinity())};
  for (int c = 0; c < 8; ++c) {
    const Eigen::Vector3d corner((c & 1) ? box.max_mm.x() : box.min_mm.x(),
                                 (c & 2) ? box.max_mm.y() : box.min_mm.y(),
                                 (c & 4) ? box.max_mm.z() : box.min_mm.z());
    const Eigen::Vector3d q = map.apply(corner);
    mapped.min_mm = mapped.min_mm.cwiseMin(q);
    mapped.max_mm = mapped.max_mm.cwiseMax(q);
  }
  mapped.min_mm.array() -= radius_mm;
  mapped.max_mm.array() += radius_mm;
  const Eigen::Vector3d centre = map.apply(x.rowwise().mean());
  const particles::Positions sites = particles::fcc_lattice_points(
      mapped, centre, a_nn_mm, [](const Eigen::Vector3d&) { return true; });
  std::vector<double> d(sites.cols());
  for (Eigen::Index s = 0; s < sites.cols(); ++s) d[s] = depth_at(map.inverse(sites.col(s)));
  std::vector<int> idx(sites.cols());
  std::iota(idx.begin(), idx.end(), 0);
  const int keep = std::min<int>(n, static_cast<int>(idx.size()));
  // The deepest `keep` sites; ties broken by index (deterministic).
  std::stable_sort(idx.begin(), idx.end(), [&](int l, int r) { return d[l] > d[r]; });
  std::sort(idx.begin(), idx.begin() + keep);
  particles::Positions out(3, keep);
  for (int s = 0; s < keep; ++s) out.col(s) = sites.col(idx[s]);
  return out;
}

}  // namespace organfit::fitting
