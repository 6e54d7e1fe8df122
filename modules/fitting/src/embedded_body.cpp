#include "organfit/fitting/embedded_body.h"

#include <Eigen/Cholesky>
#include <Eigen/Eigenvalues>
#include <Eigen/LU>
#include <algorithm>
#include <cmath>
#include <stdexcept>

#include "organfit/geometry/image_geometry.h"
#include "organfit/geometry/mask_ops.h"
#include "organfit/geometry/sample_grid.h"

namespace organfit::fitting {
namespace {
constexpr double kMaxExtentMm = 2000;  // larger than any organ: grids over it are not made
constexpr double kMaxCells = 1 << 26;  // the particle buckets (4 bytes a cell)
}  // namespace

EmbeddedBody::EmbeddedBody(std::shared_ptr<const geometry::LabelVolume> reference, GlobalMap map,
                           particles::Positions placed, particles::Positions current,
                           double support_mm)
    : reference_(std::move(reference)),
      map_(std::move(map)),
      placed_(std::move(placed)),
      current_(std::move(current)),
      h_(support_mm) {
  if (!reference_) throw std::invalid_argument("embedded body: no reference body");
  if (placed_.cols() != current_.cols())
    throw std::invalid_argument("embedded body: placed and current particle counts differ");
  if (!placed_.allFinite() || !current_.allFinite())
    throw std::invalid_argument("embedded body: a particle position is not finite");
  if (!(support_mm > 0) || !std::isfinite(support_mm))
    throw std::invalid_argument("embedded body: support must be > 0 mm");
  map_inverse_a_ = map_.affine.a.inverse();
  if (current_.cols() > 0 &&
      (current_.rowwise().maxCoeff() - current_.rowwise().minCoeff()).maxCoeff() > kMaxExtentMm)
    throw std::invalid_argument(
        "embedded body: the particles span more than 2 m (the model has come apart)");
  lo_ = current_.cols() > 0 ? Eigen::Vector3d(current_.rowwise().minCoeff())
                            : Eigen::Vector3d::Zero();
  if (current_.cols() == 0) return;
  const Eigen::Vector3d extent = current_.rowwise().maxCoeff() - lo_;
  for (int d = 0; d < 3; ++d)
    dims_[d] = static_cast<int>(std::floor(extent[d] / h_)) + 1;
  if (1.0 * dims_[0] * dims_[1] * dims_[2] > kMaxCells)
    throw std::invalid_argument(
        "embedded body: the support is too small for the particles' extent (over 2^26 cells)");
  cell_start_.assign(static_cast<size_t>(dims_.prod()) + 1, 0);
  std::vector<int> cell(static_cast<size_t>(current_.cols()));
  for (Eigen::Index i = 0; i < current_.cols(); ++i) {
    const Eigen::Vector3i c =
        ((current_.col(i) - lo_) / h_).array().floor().cast<int>().min(dims_.array() - 1);
    cell[static_cast<size_t>(i)] = c.x() + dims_.x() * (c.y() + dims_.y() * c.z());
    ++cell_start_[static_cast<size_t>(cell[static_cast<size_t>(i)]) + 1];
  }
  for (size_t c = 1; c < cell_start_.size(); ++c)
    cell_start_[c] += cell_start_[c - 1];
  cell_order_.resize(static_cast<size_t>(current_.cols()));
  std::vector<int> fill(cell_start_.begin(), cell_start_.end() - 1);
  for (Eigen::Index i = 0; i < current_.cols(); ++i)
    cell_order_[static_cast<size_t>(fill[static_cast<size_t>(cell[static_cast<size_t>(i)])]++)] =
        static_cast<int>(i);
}

Eigen::Vector3d EmbeddedBody::unmove_locally(const Eigen::Vector3d& q, bool widen_if_needed) const {
  const Eigen::Vector3d nan = Eigen::Vector3d::Constant(std::nan(""));
  if (!q.allFinite()) return nan;
  const Eigen::Vector3d c = ((q - lo_) / h_).array().floor();
  if ((c.array().abs() > 1e5).any()) return nan;  // far from every particle
  const Eigen::Vector3i cq = c.cast<int>();
  // Weighted least squares for u(x) = c0 + B (x - q) / h over the neighbours within h.
  // Where they spread too little in some direction to fix the gradient (a tip of the
  // body, where they may all lie in one lattice plane), h grows: the field is
  // extrapolated from a wider, well-spread neighbourhood instead of guessing a zero slope.
  for (int widen = 0; widen < 3; ++widen) {
    const double h = h_ * (widen == 0 ? 1.0 : widen == 1 ? 1.5 : 2.0);
    const int reach = widen == 0 ? 1 : 2;
    Eigen::Matrix4d m = Eigen::Matrix4d::Zero();
    Eigen::Matrix<double, 4, 3> r = Eigen::Matrix<double, 4, 3>::Zero();
    int count = 0;
    const double h2 = h * h;
    for (int dk = -reach; dk <= reach; ++dk)
      for (int dj = -reach; dj <= reach; ++dj)
        for (int di = -reach; di <= reach; ++di) {
          const Eigen::Vector3i cc = cq + Eigen::Vector3i(di, dj, dk);
          if ((cc.array() < 0).any() || (cc.array() >= dims_.array()).any()) continue;
          const size_t cell =
              static_cast<size_t>(cc.x() + dims_.x() * (cc.y() + dims_.y() * cc.z()));
          for (int k = cell_start_[cell]; k < cell_start_[cell + 1]; ++k) {
            const int p = cell_order_[static_cast<size_t>(k)];
            const Eigen::Vector3d d = current_.col(p) - q;
            const double s = d.squaredNorm() / h2;
            if (s >= 1) continue;
            const double w = (1 - s) * (1 - s) * (1 - s);
            const Eigen::Vector4d phi(1, d.x() / h, d.y() / h, d.z() / h);
            m.noalias() += w * phi * phi.transpose();
            r.noalias() += w * phi * (placed_.col(p) - current_.col(p)).transpose();
            ++count;
          }
        }
    if (count < 4) {
      if (widen == 0) return nan;  // beyond the body: no particle within the support
      continue;
    }
    // Spread of the neighbours (weighted covariance, in units of h^2): well-posed when its
    // smallest eigenvalue is at least (h/10)^2.
    const Eigen::Matrix3d cov = m.bottomRightCorner<3, 3>() / m(0, 0) -
                                m.block<3, 1>(1, 0) * m.block<1, 3>(0, 1) / (m(0, 0) * m(0, 0));
    Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> spread;
    spread.computeDirect(cov, Eigen::EigenvaluesOnly);
    if (spread.eigenvalues()(0) < 1e-2) {
      // Still no slope to be had (a cap of particles, as beyond the body): no answer
      // rather than a wild extrapolation.
      if (widen < 2 && widen_if_needed) continue;
      return nan;
    }
    // A faint pull of the gradient towards zero keeps a degenerate last resort solvable.
    m.bottomRightCorner<3, 3>() += 1e-9 * m(0, 0) * Eigen::Matrix3d::Identity();
    const Eigen::Matrix<double, 4, 3> coef = m.ldlt().solve(r);
    return q + coef.row(0).transpose();
  }
  return nan;
}

Eigen::Vector3d EmbeddedBody::unmap_globally(const Eigen::Vector3d& q0) const {
  return map_.inverse(q0, map_inverse_a_);
}

Eigen::Vector3d EmbeddedBody::pull_back(const Eigen::Vector3d& q) const {
  const Eigen::Vector3d q0 = unmove_locally(q);
  return q0.allFinite() ? unmap_globally(q0) : q0;
}

bool EmbeddedBody::inside(const Eigen::Vector3d& q) const {
  const Eigen::Vector3d r = pull_back(q);
  return r.allFinite() && geometry::inside_interpolated(*reference_, r);
}

geometry::Aabb EmbeddedBody::bounds() const {
  if (current_.cols() == 0) return {};
  return {current_.rowwise().minCoeff().transpose().array() - h_,
          current_.rowwise().maxCoeff().transpose().array() + h_};
}

geometry::LabelVolume EmbeddedBody::on_grid(const geometry::ImageGeometry& grid) const {
  geometry::LabelVolume out(grid);
  if (current_.cols() == 0) return out;
  const geometry::Aabb b = bounds();
  const geometry::IndexRange r = geometry::index_range(grid, b);
  if (r.empty()) return out;
  // The local displacement is smooth at the scale of the support: it is evaluated on a
  // lattice of a quarter of the support and interpolated trilinearly in between (an
  // error of ~ spacing^2 / 8 times its curvature: hundredths of a mm), directly where a
  // lattice corner has no particle near.
  const double lattice = 0.25 * h_;
  // The lattice covers the evaluated voxels (the grid's part within bounds()) only.
  Eigen::Vector3d v_lo = Eigen::Vector3d::Constant(1e300), v_hi = Eigen::Vector3d::Constant(-1e300);
  for (int c = 0; c < 8; ++c) {
    const Eigen::Vector3d corner = grid.index_to_physical(Eigen::Vector3d(
        (c & 1) ? r.hi[0] : r.lo[0], (c & 2) ? r.hi[1] : r.lo[1], (c & 4) ? r.hi[2] : r.lo[2]));
    v_lo = v_lo.cwiseMin(corner), v_hi = v_hi.cwiseMax(corner);
  }
  const Eigen::Vector3d l0 = v_lo.cwiseMax(b.min_mm).array() - lattice;
  const Eigen::Vector3d l1 = v_hi.cwiseMin(b.max_mm);
  int nl[3];
  for (int d = 0; d < 3; ++d)
    nl[d] = std::max(2, static_cast<int>(std::ceil((l1[d] - l0[d]) / lattice)) + 2);
  const long long nodes = 1LL * nl[0] * nl[1] * nl[2];
  std::vector<Eigen::Vector3d> u(static_cast<size_t>(nodes));  // q0 - q at each node
#pragma omp parallel for schedule(dynamic, 16)
  for (long long v = 0; v < nodes; ++v) {
    const int i = static_cast<int>(v % nl[0]), j = static_cast<int>((v / nl[0]) % nl[1]),
              k = static_cast<int>(v / (1LL * nl[0] * nl[1]));
    const Eigen::Vector3d q = l0 + lattice * Eigen::Vector3d(i, j, k);
    u[static_cast<size_t>(v)] = unmove_locally(q) - q;
  }
  auto node = [&](int i, int j, int k) -> const Eigen::Vector3d& {
    return u[static_cast<size_t>(i + 1LL * nl[0] * (j + 1LL * nl[1] * k))];
  };
#pragma omp parallel for schedule(dynamic, 1) collapse(2)
  for (int k = r.lo[2]; k <= r.hi[2]; ++k)
    for (int j = r.lo[1]; j <= r.hi[1]; ++j)
      for (int i = r.lo[0]; i <= r.hi[0]; ++i) {
        const Eigen::Vector3d q = grid.index_to_physical(Eigen::Vector3d(i, j, k));
        const Eigen::Vector3d t = (q - l0) / lattice;
        const Eigen::Vector3d base = t.array().floor();
        Eigen::Vector3d local = Eigen::Vector3d::Constant(std::nan(""));
        if ((base.array() >= 0).all() && base.x() < nl[0] - 1 && base.y() < nl[1] - 1 &&
            base.z() < nl[2] - 1) {
          const int a = static_cast<int>(base.x()), bb = static_cast<int>(base.y()),
                    c = static_cast<int>(base.z());
          Eigen::Vector3d sum = Eigen::Vector3d::Zero();
          geometry::for_each_trilinear_corner(t - base, [&](int di, int dj, int dk, double w) {
            sum += w * node(a + di, bb + dj, c + dk);
          });
          local = q + sum;  // NaN when a corner had no particle near
        }
        // A lattice corner beyond the particles' reach (the edge of the support, or a
        // thin tip): evaluated directly.
        if (!local.allFinite()) local = unmove_locally(q);
        out.at(i, j, k) =
            local.allFinite() && geometry::inside_interpolated(*reference_, unmap_globally(local))
                ? 1
                : 0;
      }
  return out;
}

double EmbeddedBody::volume_mm3(double voxel_mm) const {
  if (current_.cols() == 0) return 0;
  return on_grid(geometry::grid_covering(bounds(), voxel_mm, voxel_mm)).volume_mm3(1);
}

SurfaceFeet surface_feet(const particles::Positions& x, const SurfaceSamples& samples,
                         double reach) {
  SurfaceFeet feet;
  feet.offset_mm.resize(3, x.cols());
  feet.normal.resize(3, x.cols());
  const Eigen::Vector3d centroid =
      x.cols() > 0 ? Eigen::Vector3d(x.rowwise().mean()) : Eigen::Vector3d::Zero();
  for (Eigen::Index i = 0; i < x.cols(); ++i) {  // no sample within reach: deep inside
    Eigen::Vector3d away = x.col(i) - centroid;
    away = away.norm() > 1e-12 ? Eigen::Vector3d(away.normalized()) : Eigen::Vector3d::UnitX();
    feet.normal.col(i) = away, feet.offset_mm.col(i) = reach * away;
  }
  if (samples.points.cols() == 0 || !(reach > 0)) return feet;
  const geometry::SampleGrid grid(samples.points);
#pragma omp parallel for schedule(static)
  for (Eigen::Index i = 0; i < x.cols(); ++i) {
    const int nearest = grid.nearest(x.col(i), reach).first;
    if (nearest < 0) continue;
    feet.offset_mm.col(i) = samples.points.col(nearest) - x.col(i);
    feet.normal.col(i) = samples.normals.col(nearest);
  }
  return feet;
}

}  // namespace organfit::fitting
