#include "organfit/fitting/deformation.h"

#include <Eigen/Cholesky>
#include <Eigen/Eigenvalues>
#include <Eigen/LU>
#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <stdexcept>

#include "lattice_laplace.h"
#include "organfit/geometry/mask_ops.h"
#include "other_axes.h"

namespace organfit::fitting {
namespace {
constexpr double kMaxExtentMm = 2000;     // larger than any organ: grids over it are not made
constexpr double kMaxCells = 1 << 26;     // the particle buckets (4 bytes a cell)
constexpr double kMaxNodes = 6e7;         // the lattice (12 bytes a node)
constexpr double kLatticePerSupport = 3;  // nodes per support: an interpolation error of
                                          // ~ (h/3)^2 / 8 times u's curvature (on a real
                                          // GTV, within 0.04 mm of the field at h/8)

/// The particles bucketed on cells of size h: cell c holds order[start[c] .. start[c + 1]).
struct Buckets {
  Eigen::Vector3d lo = Eigen::Vector3d::Zero();
  Eigen::Vector3i dims = Eigen::Vector3i::Zero();
  std::vector<int> start, order;
  double cell_mm = 1;
  Buckets(const particles::Positions& x, double h) : cell_mm(h) {
    if (x.cols() == 0) return;
    lo = x.rowwise().minCoeff();
    const Eigen::Vector3d extent = x.rowwise().maxCoeff() - lo;
    for (int d = 0; d < 3; ++d)
      dims[d] = static_cast<int>(std::floor(extent[d] / h)) + 1;
    if (1.0 * dims[0] * dims[1] * dims[2] > kMaxCells)
      throw std::invalid_argument(
          "deformation: the support is too small for the particles' extent (over 2^26 cells)");
    start.assign(static_cast<size_t>(dims.prod()) + 1, 0);
    std::vector<int> cell(static_cast<size_t>(x.cols()));
    for (Eigen::Index i = 0; i < x.cols(); ++i) {
      const Eigen::Vector3i c =
          ((x.col(i) - lo) / h).array().floor().cast<int>().min(dims.array() - 1);
      cell[static_cast<size_t>(i)] = c.x() + dims.x() * (c.y() + dims.y() * c.z());
      ++start[static_cast<size_t>(cell[static_cast<size_t>(i)]) + 1];
    }
    for (size_t c = 1; c < start.size(); ++c)
      start[c] += start[c - 1];
    order.resize(static_cast<size_t>(x.cols()));
    std::vector<int> fill(start.begin(), start.end() - 1);
    for (Eigen::Index i = 0; i < x.cols(); ++i)
      order[static_cast<size_t>(fill[static_cast<size_t>(cell[static_cast<size_t>(i)])]++)] =
          static_cast<int>(i);
  }
};

/// The particles in bucket order (column k is particle order[k]): where they are now, and
/// their moves back to where the global stage placed them. A node's neighbours are then
/// read from a few contiguous runs instead of from all over the arrays.
struct SortedParticles {
  particles::Positions current, back;
  SortedParticles(const Buckets& b, const particles::Positions& placed,
                  const particles::Positions& now)
      : current(3, now.cols()), back(3, now.cols()) {
    for (size_t k = 0; k < b.order.size(); ++k) {
      const int p = b.order[k];
      current.col(static_cast<Eigen::Index>(k)) = now.col(p);
      back.col(static_cast<Eigen::Index>(k)) = placed.col(p) - now.col(p);
    }
  }
};

/// The moving least squares' answer at q: u(q), and whether it is kept (well posed, and
/// no less certain than one particle's displacement at q).
struct LocalFit {
  Eigen::Vector3d u = Eigen::Vector3d::Zero();
  bool kept = false;
};

/// `least_weight`: the weight of one particle at q, which the neighbours' sum must reach
/// (else no answer) and whose certainty the answer must reach (else a wider support;
/// 0: neither asked); `first_widen`: the support to start from (0: h, 1: 1.5 h, 2: 2 h).
LocalFit moving_least_squares(const Eigen::Vector3d& q, const SortedParticles& sorted,
                              const Buckets& b, double h0, double least_weight, int first_widen) {
  LocalFit out;
  if (b.dims.prod() == 0) return out;
  const Eigen::Vector3d c = ((q - b.lo) / h0).array().floor();
  if ((c.array() < -3).any() || (c.array() > b.dims.cast<double>().array() + 2).any()) return out;
  const Eigen::Vector3i cq = c.cast<int>();
  // Weighted least squares for u(x) = c0 + B (x - q) / h over the neighbours within h.
  // Where they spread too little in some direction to fix the gradient (a tip of the
  // body, where they may all lie in one lattice plane), h grows: the field is
  // extrapolated from a wider, well-spread neighbourhood instead of guessing a zero slope.
  for (int widen = first_widen; widen < 3; ++widen) {
    const double h = h0 * (widen == 0 ? 1.0 : widen == 1 ? 1.5 : 2.0);
    const int reach = widen == 0 ? 1 : 2;
    Eigen::Matrix4d m = Eigen::Matrix4d::Zero();
    Eigen::Matrix<double, 4, 3> r = Eigen::Matrix<double, 4, 3>::Zero();
    int count = 0;
    const double h2 = h * h;
    // A row of cells along x is one run of the sorted particles. Its candidates are
    // screened in chunks by a loop without branches (most lie beyond h, at random: a
    // branch on each would be mispredicted often), with a bound a little above h^2, then
    // each one kept is tested and weighed as always, in the run's order.
    constexpr int kChunk = 64;
    const double screen2 = h2 * (1 + 1e-9);
    const double* xs = sorted.current.data();
    const int i_lo = std::max(0, cq.x() - reach), i_hi = std::min(b.dims.x() - 1, cq.x() + reach);
    for (int dk = -reach; dk <= reach && i_lo <= i_hi; ++dk)
      for (int dj = -reach; dj <= reach; ++dj) {
        const int cy = cq.y() + dj, cz = cq.z() + dk;
        if (cy < 0 || cz < 0 || cy >= b.dims.y() || cz >= b.dims.z()) continue;
        const size_t row = static_cast<size_t>(b.dims.x()) * (cy + b.dims.y() * cz);
        const int run_end = b.start[row + i_hi + 1];
        for (int k0 = b.start[row + i_lo]; k0 < run_end; k0 += kChunk) {
          const int len = std::min(kChunk, run_end - k0);
          bool near[kChunk];
          for (int u = 0; u < len; ++u) {
            const double* p = xs + 3 * (k0 + u);
            const double dx = p[0] - q.x(), dy = p[1] - q.y(), dz = p[2] - q.z();
            near[u] = dx * dx + dy * dy + dz * dz < screen2;
          }
          for (int u = 0; u < len; ++u) {
            if (!near[u]) continue;
            const int k = k0 + u;
            const Eigen::Vector3d d = sorted.current.col(k) - q;
            const double d2 = d.squaredNorm();
            if (d2 >= h2) continue;  // beyond h (without a division)
            const double s = d2 / h2;
            if (s >= 1) continue;
            const double w = (1 - s) * (1 - s) * (1 - s);
            // m += w phi phi^T and r += w phi back^T, phi = (1, d / h), entry by entry in
            // registers (as Eigen's outer product rounds them: (w phi_i) phi_j), not
            // through a vector built on the stack and read back whole.
            const double phi[4] = {1, d.x() / h, d.y() / h, d.z() / h};
            const double* back = sorted.back.data() + 3 * k;
            for (int i = 0; i < 4; ++i) {
              const double wi = w * phi[i];
              for (int j = 0; j < 4; ++j)
                m(i, j) += wi * phi[j];
              for (int j = 0; j < 3; ++j)
                r(i, j) += wi * back[j];
            }
            ++count;
          }
        }
      }
    if (count < 4) {
      if (widen == 0) return out;  // beyond the body: no particle within the support
      continue;
    }
    // Spread of the neighbours (weighted covariance, in units of h^2): well-posed when its
    // smallest eigenvalue is at least (h/10)^2.
    const Eigen::Matrix3d cov = m.bottomRightCorner<3, 3>() / m(0, 0) -
                                m.block<3, 1>(1, 0) * m.block<1, 3>(0, 1) / (m(0, 0) * m(0, 0));
    Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> spread;
    spread.computeDirect(cov, Eigen::EigenvaluesOnly);
    if (spread.eigenvalues()(0) < 1e-2) continue;  // a cap of particles: no slope to be had
    if (m(0, 0) < least_weight) return out;        // too few near q to trust
    m.bottomRightCorner<3, 3>() += 1e-9 * m(0, 0) * Eigen::Matrix3d::Identity();
    const Eigen::LDLT<Eigen::Matrix4d> solve = m.ldlt();
    // The answer's variance as the weights state it (a particle of weight w known to
    // s^2 / w): s^2 (M^-1)_00. That is s^2 / sum w at the neighbours' centroid, and
    // grows as q lies farther from them along a direction they spread little in: a
    // gradient from a thin layer, extrapolated past the surface, amplifies the particles'
    // jitter into folds. At most one particle's at q, or a wider support.
    if (least_weight > 0 && solve.solve(Eigen::Vector4d::UnitX())(0) * least_weight > 1) continue;
    const Eigen::Matrix<double, 4, 3> coef = solve.solve(r);
    out.u = coef.row(0).transpose();
    out.kept = out.u.allFinite();
    return out;
  }
  return out;
}

/// A cell's corner values (corner c at offsets (c & 1, c >> 1 & 1, c >> 2 & 1)) as its
/// edges' differences: along[a][e], the 4 edges along axis a, e indexing the other two
/// axes' offsets (the lower axis first).
Deformation::CellEdges cell_edges(const Eigen::Vector3d (&corner)[8]) {
  Deformation::CellEdges cell;
  for (int e = 0; e < 4; ++e) {
    const int p = e & 1, q = e >> 1;
    cell.along[0][e] = corner[1 + 2 * p + 4 * q] - corner[2 * p + 4 * q];
    cell.along[1][e] = corner[p + 2 + 4 * q] - corner[p + 4 * q];
    cell.along[2][e] = corner[p + 2 * q + 4] - corner[p + 2 * q];
  }
  return cell;
}

/// The gradient of the cell's trilinear interpolant at fraction f of the cell (spacing in
/// mm): along each axis, the bilinear mean of its 4 edges' differences over the other two.
Eigen::Matrix3d cell_gradient(const Deformation::CellEdges& cell, const Eigen::Vector3d& f,
                              double spacing) {
  Eigen::Matrix3d g;
  for (int a = 0; a < 3; ++a) {
    const auto [b, c] = detail::other_axes(a);
    const double s = f(b), t = f(c);
    g.col(a) = ((1 - s) * (1 - t) * cell.along[a][0] + s * (1 - t) * cell.along[a][1] +
                (1 - s) * t * cell.along[a][2] + s * t * cell.along[a][3]) /
               spacing;
  }
  return g;
}

}  // namespace

Deformation::Deformation() = default;

Deformation::Deformation(GlobalMap map, particles::Positions placed, particles::Positions current,
                         double support_mm)
    : map_(std::move(map)), h_(support_mm) {
  if (placed.cols() != current.cols())
    throw std::invalid_argument("deformation: placed and current particle counts differ");
  if (!placed.allFinite() || !current.allFinite())
    throw std::invalid_argument("deformation: a particle position is not finite");
  if (!(support_mm > 0) || !std::isfinite(support_mm))
    throw std::invalid_argument("deformation: support must be > 0 mm");
  map_inverse_a_ = map_.affine.a.inverse();
  map_fields_ = ShearFieldTable(map_.fields);
  identity_ = map_.identity();  // until a local displacement is made below
  if (current.cols() == 0) return;
  const Eigen::Vector3d lo = current.rowwise().minCoeff().cwiseMin(placed.rowwise().minCoeff());
  const Eigen::Vector3d hi = current.rowwise().maxCoeff().cwiseMax(placed.rowwise().maxCoeff());
  if ((hi - lo).maxCoeff() > kMaxExtentMm)
    throw std::invalid_argument(
        "deformation: the particles span more than 2 m (the model has come apart)");
  // Today's organ lies within h of the placed or current particles, moved by at most the
  // largest |u| (the harmonic part has no interior extremum: it stays within the fitted
  // part, which stays within the particles' moves up to the affine extrapolation).
  const double largest_move = (placed - current).colwise().norm().maxCoeff();
  particle_box_ = {lo.array() - h_ - largest_move, hi.array() + h_ + largest_move};
  if (largest_move == 0) return;  // at rest: u is zero everywhere
  spacing_ = lattice_mm();
  // D beyond the particles, and one node more for the rim the moving least squares answers.
  const double fall_mm = std::max(2 * h_, 2 * largest_move);  // D
  const double margin = fall_mm + spacing_;
  origin_ = lo.array() - margin;
  for (int d = 0; d < 3; ++d)
    n_[d] = static_cast<int>(std::ceil((hi[d] - lo[d] + 2 * margin) / spacing_)) + 1;
  if (1.0 * n_[0] * n_[1] * n_[2] > kMaxNodes)
    throw std::invalid_argument(
        "deformation: the lattice of the displacement would exceed 6e7 nodes");
  const long long nodes = 1LL * n_[0] * n_[1] * n_[2];
  values_.assign(static_cast<size_t>(nodes), Eigen::Vector3f::Zero());
  identity_ = false;
  std::vector<std::uint8_t> fitted(static_cast<size_t>(nodes), 0);  // the MLS's answer kept
  const long long step[3] = {1, n_[0], 1LL * n_[0] * n_[1]};
  geometry::ImageGeometry lattice;  // the nodes as a grid, for distances over it
  lattice.size = {n_[0], n_[1], n_[2]};
  lattice.spacing_mm.setConstant(spacing_);
  lattice.origin_mm = origin_;
  // Nodes with no particle within h, which the moving least squares do not answer and
  // are not asked: their distance to the nearest node that has a particle nearest to it
  // exceeds h by more than half a cell's diagonal.
  std::vector<std::uint8_t> unreached(static_cast<size_t>(nodes), 0);
  {
    std::vector<std::uint8_t> seed(static_cast<size_t>(nodes), 0);
    for (Eigen::Index p = 0; p < current.cols(); ++p) {
      const Eigen::Vector3i at =
          ((current.col(p) - origin_) / spacing_).array().round().cast<int>();
      seed[static_cast<size_t>(at.x() + step[1] * at.y() + step[2] * at.z())] = 1;
    }
    const geometry::GridBuffer<double> d2 = geometry::squared_distance_transform(seed, lattice);
    const double reach = h_ + 0.5 * std::sqrt(3.0) * spacing_;
#pragma omp parallel for schedule(static)
    for (long long v = 0; v < nodes; ++v)
      unreached[static_cast<size_t>(v)] = d2[static_cast<size_t>(v)] > reach * reach;
  }
  {
    const Buckets buckets(current, h_);
    const SortedParticles sorted(buckets, placed, current);
#pragma omp parallel for schedule(dynamic, 64)
    for (long long v = 0; v < nodes; ++v) {
      if (unreached[static_cast<size_t>(v)]) continue;
      const LocalFit f = moving_least_squares(node(v), sorted, buckets, h_, 1.0, 0);
      if (!f.kept) continue;
      values_[static_cast<size_t>(v)] = f.u.cast<float>();
      fitted[static_cast<size_t>(v)] = 1;
    }
    // The rim: the other nodes of every cell with a node kept above, answered too, so that
    // a point it answers is interpolated from its answers alone (an affine motion
    // exactly) rather than mixed with the harmonic part. Beyond the weight of one
    // particle, from a support of 2h: an extrapolation from the few particles within h
    // tilts with them (it folded a real GTV twisted 10 mm; docs/decisions.md).
    std::vector<std::uint8_t> rim(static_cast<size_t>(nodes), 0);
#pragma omp parallel for schedule(dynamic, 64)
    for (long long v = 0; v < nodes; ++v) {
      if (fitted[static_cast<size_t>(v)]) continue;
      const int at[3] = {static_cast<int>(v % n_[0]), static_cast<int>((v / n_[0]) % n_[1]),
                         static_cast<int>(v / step[2])};
      bool near = false;
      for (int c = 0; c < 27 && !near; ++c) {
        const int d[3] = {c % 3 - 1, (c / 3) % 3 - 1, c / 9 - 1};
        bool on = true;
        for (int a = 0; a < 3; ++a)
          on = on && at[a] + d[a] >= 0 && at[a] + d[a] < n_[a];
        near =
            on && fitted[static_cast<size_t>(v + d[0] * step[0] + d[1] * step[1] + d[2] * step[2])];
      }
      if (!near) continue;
      const LocalFit f = moving_least_squares(node(v), sorted, buckets, h_, 0.0, 2);
      if (!f.kept) continue;
      values_[static_cast<size_t>(v)] = f.u.cast<float>();
      rim[static_cast<size_t>(v)] = 1;
    }
    for (size_t v = 0; v < rim.size(); ++v)
      fitted[v] |= rim[v];
  }
  for (const auto f : fitted)
    fitted_nodes_ += f;
  // u where the moving least squares did not answer: harmonic, held at its answers, and
  // at zero on the lattice's faces and at the nodes farther than D from every answered
  // node: it falls over D from where the particles' answers end, as it does towards the
  // faces, but also in a concave organ's hollows, which its box encloses (on a liver, a
  // quarter of its box, 7 in 10 of the free nodes the faces alone left).
  {
    const geometry::GridBuffer<double> d2 = geometry::squared_distance_transform(fitted, lattice);
    std::vector<std::uint8_t>& held = fitted;  // from here: u given (answered, or zero)
#pragma omp parallel for schedule(static)
    for (long long v = 0; v < nodes; ++v)
      held[static_cast<size_t>(v)] |= d2[static_cast<size_t>(v)] > fall_mm * fall_mm;
    harmonic_nodes_ = solve_harmonic_part(held);
  }
  // det(grad phi^-1) over the cells, at the centres of their eight octants (within a cell
  // the trilinear gradient varies, and a fold need not reach the centre).
  double lo_det = 1, hi_det = 1;
#pragma omp parallel for collapse(2) reduction(min : lo_det) reduction(max : hi_det)
  for (int k = 0; k < n_[2] - 1; ++k)
    for (int j = 0; j < n_[1] - 1; ++j)
      for (int i = 0; i < n_[0] - 1; ++i) {
        Eigen::Vector3d corner[8];
        cell_corners(i + step[1] * j + step[2] * k, corner);
        bool still = true;  // u = 0 at every corner: det 1 throughout, as started
        for (const auto& c : corner)
          still = still && c.isZero(0);
        if (still) continue;
        const Deformation::CellEdges cell = cell_edges(corner);
        for (int octant = 0; octant < 8; ++octant) {
          const Eigen::Vector3d f(octant & 1 ? 0.75 : 0.25, octant & 2 ? 0.75 : 0.25,
                                  octant & 4 ? 0.75 : 0.25);
          const double det =
              (Eigen::Matrix3d::Identity() + cell_gradient(cell, f, spacing_)).determinant();
          lo_det = std::min(lo_det, det), hi_det = std::max(hi_det, det);
        }
      }
  min_det_ = lo_det, max_det_ = hi_det;
  // u's largest size, and its gradient's bound at each node (for on_grid's stretch): the
  // largest edge difference either side along each axis, over the spacing, kept by blocks.
  double largest_u = 0;
#pragma omp parallel for schedule(static) reduction(max : largest_u)
  for (long long v = 0; v < nodes; ++v)
    largest_u = std::max(largest_u, values_[static_cast<size_t>(v)].cast<double>().norm());
  grad_u_sq_ = geometry::BlockMaxima::of({n_[0], n_[1], n_[2]}, [&](int i, int j, int k) {
    const int at[3] = {i, j, k};
    const long long v = i + step[1] * j + step[2] * k;
    const Eigen::Vector3d u = values_[static_cast<size_t>(v)].cast<double>();
    double sq = 0;
    for (int d = 0; d < 3; ++d) {
      double edge = 0;
      if (at[d] > 0)
        edge = (values_[static_cast<size_t>(v - step[d])].cast<double>() - u).squaredNorm();
      if (at[d] + 1 < n_[d])
        edge = std::max(
            edge, (values_[static_cast<size_t>(v + step[d])].cast<double>() - u).squaredNorm());
      sq += edge;
    }
    return sq / (spacing_ * spacing_);
  });
  largest_u_mm_ = largest_u;
}

StretchBound Deformation::map_inverse_stretch(const geometry::Aabb& box) const {
  const geometry::Aabb grown{box.min_mm.array() - largest_u_mm_,
                             box.max_mm.array() + largest_u_mm_};
  return map_.inverse_stretch(grown, map_fields_.error());
}

double Deformation::u_gradient_bound(const geometry::Aabb& box) const {
  if (grad_u_sq_.empty()) return 0;  // no lattice: u is zero everywhere
  // The nodes at the corners of the cells the box touches (clamped to the lattice).
  std::array<int, 3> lo, hi;
  for (int d = 0; d < 3; ++d) {
    const double a = std::floor((box.min_mm[d] - origin_[d]) / spacing_);
    const double b = std::floor((box.max_mm[d] - origin_[d]) / spacing_) + 1;
    if (!std::isfinite(a) || !std::isfinite(b)) return std::sqrt(grad_u_sq_.largest());
    lo[d] = static_cast<int>(std::clamp(a, 0.0, n_[d] - 1.0));
    hi[d] = static_cast<int>(std::clamp(b, 0.0, n_[d] - 1.0));
  }
  return std::sqrt(grad_u_sq_.over(lo, hi));
}

double Deformation::min_volume_ratio() const {
  return max_det_ > 0 ? 1.0 / max_det_ : -std::numeric_limits<double>::infinity();
}

double Deformation::max_volume_ratio() const {
  return min_det_ > 0 ? 1.0 / min_det_ : std::numeric_limits<double>::infinity();
}

long long Deformation::solve_harmonic_part(const std::vector<std::uint8_t>& held) {
  const detail::LatticeFreeNodes lattice = detail::lattice_free_nodes(n_, held);
  const size_t nf = lattice.free_nodes.size();
  if (nf == 0) return 0;
  const auto count = static_cast<Eigen::Index>(nf);
  Eigen::Matrix3Xd rhs(3, count), x(3, count);
  const long long step[3] = {1, n_[0], 1LL * n_[0] * n_[1]};
  // Node by node on threads (3.3M free nodes on a million particles' lattice): each
  // node's sum is its own.
#pragma omp parallel for schedule(static)
  for (Eigen::Index f = 0; f < count; ++f) {
    const auto at = static_cast<size_t>(f);
    Eigen::Vector3d sum = Eigen::Vector3d::Zero();  // of the held neighbours' values
    for (int d = 0; d < 3; ++d)
      for (int side = 0; side < 2; ++side)
        if (lattice.neighbours[at][static_cast<size_t>(2 * d + side)] < 0)  // 0 on a face
          sum += values_[static_cast<size_t>(lattice.free_nodes[at] + (side ? step[d] : -step[d]))]
                     .cast<double>();
    rhs.col(f) = sum;
    x.col(f).setZero();
  }
  detail::solve_lattice_laplace(lattice, rhs, x);
#pragma omp parallel for schedule(static)
  for (Eigen::Index f = 0; f < count; ++f)
    values_[static_cast<size_t>(lattice.free_nodes[static_cast<size_t>(f)])] =
        x.col(f).cast<float>();
  return static_cast<long long>(nf);
}

double Deformation::lattice_mm() const {
  return h_ / kLatticePerSupport;
}

Eigen::Vector3d Deformation::node(long long v) const {
  const int i = static_cast<int>(v % n_[0]), j = static_cast<int>((v / n_[0]) % n_[1]),
            k = static_cast<int>(v / (1LL * n_[0] * n_[1]));
  return origin_ + spacing_ * Eigen::Vector3d(i, j, k);
}

geometry::Aabb Deformation::local_box() const {
  if (values_.empty()) return {};
  return {origin_, origin_ + spacing_ * (n_.cast<double>().array() - 1).matrix()};
}

void Deformation::cell_corners(long long v0, Eigen::Vector3d (&corner)[8]) const {
  const long long step[3] = {1, n_[0], 1LL * n_[0] * n_[1]};
  for (int c = 0; c < 8; ++c)
    corner[c] = values_[static_cast<size_t>(v0 + (c & 1) * step[0] + ((c >> 1) & 1) * step[1] +
                                            ((c >> 2) & 1) * step[2])]
                    .cast<double>();
}

long long Deformation::cell_at(const Eigen::Vector3d& q, Eigen::Vector3d& f) const {
  if (values_.empty()) return -1;
  const Eigen::Vector3d t = (q - origin_) / spacing_;
  const Eigen::Vector3d base = t.array().floor();
  if ((base.array() < 0).any() || base.x() >= n_[0] - 1 || base.y() >= n_[1] - 1 ||
      base.z() >= n_[2] - 1)
    return -1;
  f = t - base;
  return static_cast<long long>(base.x()) +
         1LL * n_[0] *
             (static_cast<long long>(base.y()) + 1LL * n_[1] * static_cast<long long>(base.z()));
}

Eigen::Vector3d Deformation::pull_back(const Eigen::Vector3d& q) const {
  if (!q.allFinite() || identity_) return q;  // the identity's q exactly, not M^-1(q)'s rounding
  Eigen::Vector3d f;
  const long long v0 = cell_at(q, f);
  if (v0 < 0) return map_.inverse(q, map_inverse_a_, map_fields_);
  Eigen::Vector3d u = Eigen::Vector3d::Zero();
  Eigen::Vector3d corner[8];
  cell_corners(v0, corner);
  for (int c = 0; c < 8; ++c) {
    const int di = c & 1, dj = (c >> 1) & 1, dk = (c >> 2) & 1;
    const double wx = di ? f.x() : 1 - f.x(), wy = dj ? f.y() : 1 - f.y(),
                 wz = dk ? f.z() : 1 - f.z();
    u += wx * wy * wz * corner[c];
  }
  return map_.inverse(q + u, map_inverse_a_, map_fields_);
}

Eigen::Vector3d Deformation::push_forward(const Eigen::Vector3d& r) const {
  // Newton on phi^-1(q) = r, the Jacobian by central differences, from M(r).
  Eigen::Vector3d q = map_.apply(r);
  for (int it = 0; it < 50; ++it) {
    const Eigen::Vector3d e = pull_back(q) - r;
    if (e.norm() < 1e-10) break;
    Eigen::Matrix3d j;
    for (int d = 0; d < 3; ++d) {
      const Eigen::Vector3d step = 1e-4 * Eigen::Vector3d::Unit(d);
      j.col(d) = (pull_back(q + step) - pull_back(q - step)) / 2e-4;
    }
    q -= j.fullPivLu().solve(e);
  }
  return q;
}

double Deformation::volume_ratio(const Eigen::Vector3d& q) const {
  CellCache cache;
  return volume_ratio(q, cache);
}

double Deformation::volume_ratio(const Eigen::Vector3d& q, CellCache& cache) const {
  if (!q.allFinite() || identity_) return 1.0;
  Eigen::Vector3d f;
  const long long v0 = cell_at(q, f);
  if (v0 < 0) return 1.0;  // the global map alone, which keeps volume
  if (cache.cell != v0) {
    Eigen::Vector3d corner[8];
    cell_corners(v0, corner);
    cache.edges = cell_edges(corner);
    cache.cell = v0;
  }
  // The global map keeps volume: det(grad phi^-1) = det(I + grad u).
  const double det =
      (Eigen::Matrix3d::Identity() + cell_gradient(cache.edges, f, spacing_)).determinant();
  return det > 0 ? 1.0 / det : std::numeric_limits<double>::infinity();
}

}  // namespace organfit::fitting
