#include "lattice_laplace.h"

#include <Eigen/SparseCholesky>
#include <Eigen/SparseCore>
#include <algorithm>
#include <cmath>
#include <memory>

namespace organfit::fitting::detail {

LatticeFreeNodes lattice_free_nodes(const Eigen::Vector3i& dims,
                                    const std::vector<std::uint8_t>& held) {
  LatticeFreeNodes l;
  l.dims = dims;
  const long long nx = dims[0], nxy = nx * dims[1];
  l.free_index.assign(static_cast<size_t>(nxy * dims[2]), -1);
  for (int k = 1; k + 1 < dims[2]; ++k)
    for (int j = 1; j + 1 < dims[1]; ++j)
      for (int i = 1; i + 1 < dims[0]; ++i) {
        const long long v = i + nx * j + nxy * k;
        if (held[static_cast<size_t>(v)]) continue;
        l.free_index[static_cast<size_t>(v)] = static_cast<int>(l.free_nodes.size());
        l.free_nodes.push_back(v);
      }
  l.neighbours.resize(l.free_nodes.size());
  const long long step[3] = {1, nx, nxy};
  for (size_t f = 0; f < l.free_nodes.size(); ++f)
    for (int d = 0; d < 3; ++d)
      for (int side = 0; side < 2; ++side)
        l.neighbours[f][static_cast<size_t>(2 * d + side)] =
            l.free_index[static_cast<size_t>(l.free_nodes[f] + (side ? step[d] : -step[d]))];
  return l;
}

namespace {

using Field = Eigen::Matrix3Xd;  // three components per free node

/// The stencil at free node i: 6 v_i - its free neighbours' v.
inline Eigen::Vector3d stencil(const LatticeFreeNodes& l, const Field& v, Eigen::Index i) {
  Eigen::Vector3d s = 6 * v.col(i);
  for (int nb : l.neighbours[static_cast<size_t>(i)])
    if (nb >= 0) s -= v.col(nb);
  return s;
}

/// out = scale (6 v - the free neighbours' v); returns v . out per component.
Eigen::Vector3d apply(const LatticeFreeNodes& l, double scale, const Field& v, Field& out) {
  const auto n = static_cast<Eigen::Index>(l.free_nodes.size());
  out.resize(3, n);
  double s0 = 0, s1 = 0, s2 = 0;
#pragma omp parallel for schedule(static) reduction(+ : s0, s1, s2)
  for (Eigen::Index i = 0; i < n; ++i) {
    const Eigen::Vector3d s = scale * stencil(l, v, i);
    out.col(i) = s;
    s0 += v(0, i) * s(0), s1 += v(1, i) * s(1), s2 += v(2, i) * s(2);
  }
  return {s0, s1, s2};
}

/// y += diag(a) x, node by node on threads (each entry its own: the values one pass
/// gives).
void add_scaled(Field& y, const Eigen::Array3d& a, const Field& x) {
  const Eigen::Index n = y.cols();
#pragma omp parallel for schedule(static)
  for (Eigen::Index i = 0; i < n; ++i)
    for (int d = 0; d < 3; ++d)
      y(d, i) += a[d] * x(d, i);
}

/// y = x + diag(a) y, likewise.
void scaled_plus(Field& y, const Eigen::Array3d& a, const Field& x) {
  const Eigen::Index n = y.cols();
#pragma omp parallel for schedule(static)
  for (Eigen::Index i = 0; i < n; ++i)
    for (int d = 0; d < 3; ++d)
      y(d, i) = x(d, i) + a[d] * y(d, i);
}

/// out = a x, node by node on threads.
void scaled(double a, const Field& x, Field& out) {
  const Eigen::Index n = x.cols();
  out.resize(3, n);
#pragma omp parallel for schedule(static)
  for (Eigen::Index i = 0; i < n; ++i)
    out.col(i) = a * x.col(i);
}

/// The node counts of the next coarser lattice: its node I is the fine node 2I.
Eigen::Vector3i coarser_dims(const Eigen::Vector3i& dims) {
  return (dims.array() - 1) / 2 + 1;
}

/// The next coarser lattice: free where the fine node 2I is (off the coarse faces).
LatticeFreeNodes coarser(const LatticeFreeNodes& fine) {
  const Eigen::Vector3i dc = coarser_dims(fine.dims);
  const long long nx = fine.dims[0], nxy = nx * fine.dims[1];
  std::vector<std::uint8_t> held(static_cast<size_t>(1LL * dc[0] * dc[1] * dc[2]), 1);
  for (int k = 1; k + 1 < dc[2]; ++k)
    for (int j = 1; j + 1 < dc[1]; ++j)
      for (int i = 1; i + 1 < dc[0]; ++i)
        if (fine.free_index[static_cast<size_t>(2 * i + nx * 2 * j + nxy * 2 * k)] >= 0)
          held[static_cast<size_t>(i + 1LL * dc[0] * (j + 1LL * dc[1] * k))] = 0;
  return lattice_free_nodes(dc, held);
}

/// For each of a node's coordinates on the fine lattice, the coarse coordinates it
/// interpolates from and their weights (trilinear: an even one sits on a coarse node).
struct Spans {
  int at[3][2], count[3];
  double weight[3][2];
  Spans(long long v, const Eigen::Vector3i& dims) {
    const long long c[3] = {v % dims[0], (v / dims[0]) % dims[1], v / (1LL * dims[0] * dims[1])};
    for (int d = 0; d < 3; ++d) {
      if (c[d] % 2 == 0) {
        at[d][0] = static_cast<int>(c[d] / 2), weight[d][0] = 1, count[d] = 1;
      } else {
        at[d][0] = static_cast<int>((c[d] - 1) / 2), at[d][1] = at[d][0] + 1;
        weight[d][0] = weight[d][1] = 0.5, count[d] = 2;
      }
    }
  }
};

/// The hierarchy and the V-cycle: damped Jacobi smoothing (2 sweeps before and after,
/// weight 6/7, the 7-point stencil's best smoother of its kind), the residual carried
/// down by P^T and the correction up by P (trilinear), each coarser operator the
/// stencil again at twice the scale (P^T A P of a smooth field, P^T summing 8 weights),
/// and a sparse Cholesky factorisation at the coarsest. Symmetric and positive: a
/// preconditioner for conjugate gradients.
class Multigrid {
 public:
  explicit Multigrid(const LatticeFreeNodes& finest) : finest_(finest) {
    const LatticeFreeNodes* at = &finest;
    while (at->free_nodes.size() > kCoarsest) {
      if (coarser_dims(at->dims).minCoeff() < 3) break;  // no interior left to coarsen to
      coarse_.push_back(std::make_unique<LatticeFreeNodes>(coarser(*at)));
      at = coarse_.back().get();
      if (at->free_nodes.empty()) {
        coarse_.pop_back();
        at = coarse_.empty() ? &finest : coarse_.back().get();
        break;
      }
    }
    // The coarsest level, factorised.
    const LatticeFreeNodes& c = level(static_cast<int>(coarse_.size()));
    const double s = scale(static_cast<int>(coarse_.size()));
    std::vector<Eigen::Triplet<double>> t;
    for (size_t f = 0; f < c.free_nodes.size(); ++f) {
      t.emplace_back(static_cast<int>(f), static_cast<int>(f), 6 * s);
      for (int nb : c.neighbours[f])
        if (nb >= 0) t.emplace_back(static_cast<int>(f), nb, -s);
    }
    const auto n = static_cast<Eigen::Index>(c.free_nodes.size());
    Eigen::SparseMatrix<double> a(n, n);
    a.setFromTriplets(t.begin(), t.end());
    cholesky_.compute(a);
    e_.resize(coarse_.size() + 1), t_.resize(coarse_.size() + 1), f_.resize(coarse_.size() + 1);
  }

  /// M^-1 r, in the hierarchy's buffer (valid until the next call). Not thread-safe.
  const Field& precondition(const Field& r) const {
    cycle(0, r);
    return e_[0];
  }

 private:
  static constexpr size_t kCoarsest = 4000;  // free nodes factorised directly (~1 ms)
  static constexpr double kJacobiWeight = 6.0 / 7.0;
  static constexpr int kSweeps = 2;

  const LatticeFreeNodes& level(int l) const {
    return l == 0 ? finest_ : *coarse_[static_cast<size_t>(l - 1)];
  }
  static double scale(int l) { return std::ldexp(1.0, l); }

  /// out = e + step (f - A e) (one damped Jacobi sweep), or with `residual` f - A e; one
  /// pass over the nodes.
  static void sweep(const LatticeFreeNodes& l, double s, double step, const Field& f,
                    const Field& e, Field& out, bool residual) {
    const auto n = static_cast<Eigen::Index>(l.free_nodes.size());
    out.resize(3, n);
#pragma omp parallel for schedule(static)
    for (Eigen::Index i = 0; i < n; ++i) {
      const Eigen::Vector3d r = f.col(i) - s * stencil(l, e, i);
      out.col(i) = residual ? r : Eigen::Vector3d(e.col(i) + step * r);
    }
  }

  /// The V-cycle at level l for right-hand side f; its answer in e_[l].
  void cycle(int l, const Field& f) const {
    const auto at = static_cast<size_t>(l);
    if (l == static_cast<int>(coarse_.size())) {
      e_[at] = cholesky_.solve(f.transpose()).transpose();
      return;
    }
    const LatticeFreeNodes& fine = level(l);
    const LatticeFreeNodes& coarse = level(l + 1);
    const double s = scale(l), step = kJacobiWeight / (6 * s);
    scaled(step, f, e_[at]);  // the first sweep, from zero
    for (int k = 1; k < kSweeps; ++k) {
      sweep(fine, s, step, f, e_[at], t_[at], false);
      e_[at].swap(t_[at]);
    }
    sweep(fine, s, step, f, e_[at], t_[at], true);
    restrict(fine, coarse, t_[at], f_[at + 1]);
    cycle(l + 1, f_[at + 1]);
    prolong_add(fine, coarse, e_[at + 1], e_[at]);
    for (int k = 0; k < kSweeps; ++k) {
      sweep(fine, s, step, f, e_[at], t_[at], false);
      e_[at].swap(t_[at]);
    }
  }

  /// P^T r: each coarse free node gathers its fine free nodes' values by their weights.
  static void restrict(const LatticeFreeNodes& fine, const LatticeFreeNodes& coarse, const Field& r,
                       Field& out) {
    const auto n = static_cast<Eigen::Index>(coarse.free_nodes.size());
    out.resize(3, n);
    const long long nx = fine.dims[0], nxy = nx * fine.dims[1];
#pragma omp parallel for schedule(static)
    for (Eigen::Index c = 0; c < n; ++c) {
      const long long v = coarse.free_nodes[static_cast<size_t>(c)];
      const long long ci = v % coarse.dims[0], cj = (v / coarse.dims[0]) % coarse.dims[1],
                      ck = v / (1LL * coarse.dims[0] * coarse.dims[1]);
      Eigen::Vector3d sum = Eigen::Vector3d::Zero();
      for (int dk = -1; dk <= 1; ++dk)
        for (int dj = -1; dj <= 1; ++dj)
          for (int di = -1; di <= 1; ++di) {
            const long long fi = 2 * ci + di, fj = 2 * cj + dj, fk = 2 * ck + dk;
            if (fi < 0 || fj < 0 || fk < 0 || fi >= fine.dims[0] || fj >= fine.dims[1] ||
                fk >= fine.dims[2])
              continue;
            const int f = fine.free_index[static_cast<size_t>(fi + nx * fj + nxy * fk)];
            if (f < 0) continue;
            const double w = (di ? 0.5 : 1.0) * (dj ? 0.5 : 1.0) * (dk ? 0.5 : 1.0);
            sum += w * r.col(f);
          }
      out.col(c) = sum;
    }
  }

  /// out += P e: each fine free node interpolates its coarse free nodes' values.
  static void prolong_add(const LatticeFreeNodes& fine, const LatticeFreeNodes& coarse,
                          const Field& e, Field& out) {
    const auto n = static_cast<Eigen::Index>(fine.free_nodes.size());
    const long long cx = coarse.dims[0], cxy = cx * coarse.dims[1];
#pragma omp parallel for schedule(static)
    for (Eigen::Index f = 0; f < n; ++f) {
      const Spans s(fine.free_nodes[static_cast<size_t>(f)], fine.dims);
      Eigen::Vector3d sum = Eigen::Vector3d::Zero();
      for (int a = 0; a < s.count[2]; ++a)
        for (int b = 0; b < s.count[1]; ++b)
          for (int c = 0; c < s.count[0]; ++c) {
            const int k = coarse.free_index[static_cast<size_t>(s.at[0][c] + cx * s.at[1][b] +
                                                                cxy * s.at[2][a])];
            if (k >= 0) sum += s.weight[0][c] * s.weight[1][b] * s.weight[2][a] * e.col(k);
          }
      out.col(f) += sum;
    }
  }

  const LatticeFreeNodes& finest_;
  std::vector<std::unique_ptr<LatticeFreeNodes>> coarse_;
  Eigen::SimplicialLDLT<Eigen::SparseMatrix<double>> cholesky_;
  // Per level: the cycle's answer, a second buffer for the sweeps, the right-hand side.
  mutable std::vector<Field> e_, t_, f_;
};

/// Conjugate gradients for the three components at once: three independent iterations
/// (each its own step lengths and stop, |r| <= 1e-5 |rhs|) sharing the passes over the
/// nodes, preconditioned by `precondition(r)` (M^-1 r, a reference valid until its next
/// call: no buffer of its own here). In place from the start in x. Returns the iterations
/// taken, or -1 after `most` of them or where the iteration stops being positive definite
/// (a preconditioner that does not serve).
template <class Precondition>
int conjugate_gradients(const LatticeFreeNodes& lattice, const Field& rhs, Field& x, int most,
                        Precondition&& precondition) {
  const auto n = static_cast<Eigen::Index>(lattice.free_nodes.size());
  Field ap(3, n);
  apply(lattice, 1.0, x, ap);
  Field r = rhs - ap;
  const Field* z = &precondition(r);
  Field p = *z;
  Eigen::Vector3d rz = r.cwiseProduct(*z).rowwise().sum();
  const Eigen::Vector3d stop =
      1e-10 * rhs.rowwise().squaredNorm().cwiseMax(Eigen::Vector3d::Constant(1e-30));
  for (int it = 0; it < most; ++it) {
    const Eigen::Array3d active = (r.rowwise().squaredNorm().array() > stop.array()).cast<double>();
    if (!active.any()) return it;
    const Eigen::Vector3d pap = apply(lattice, 1.0, p, ap);
    if ((active > 0 && (pap.array() <= 0 || rz.array() <= 0)).any()) return -1;
    // A component that has stopped takes no step.
    const Eigen::Array3d alpha = (active > 0).select(rz.array() / pap.array(), 0.0);
    add_scaled(x, alpha, p);
    add_scaled(r, -alpha, ap);
    z = &precondition(r);
    const Eigen::Vector3d rz_next = r.cwiseProduct(*z).rowwise().sum();
    const Eigen::Array3d beta = (active > 0).select(rz_next.array() / rz.array(), 0.0);
    rz = rz_next;
    scaled_plus(p, beta, *z);
  }
  return -1;
}

}  // namespace

int solve_lattice_laplace(const LatticeFreeNodes& lattice, const Eigen::Matrix3Xd& rhs,
                          Eigen::Matrix3Xd& x) {
  if (lattice.free_nodes.empty()) return 0;
  // Preconditioned, a few tens at most (9 on a 2 L lung's lattice).
  constexpr int kMostPreconditioned = 200;
  const Multigrid mg(lattice);
  const int taken =
      conjugate_gradients(lattice, rhs, x, kMostPreconditioned,
                          [&mg](const Field& r) -> const Field& { return mg.precondition(r); });
  if (taken >= 0) return taken;
  // The preconditioner did not serve (not positive on this lattice, or too slow): plain
  // conjugate gradients from where it got.
  const int plain =
      conjugate_gradients(lattice, rhs, x, 5000, [](const Field& r) -> const Field& { return r; });
  return kMostPreconditioned + std::max(plain, 0);
}

}  // namespace organfit::fitting::detail
