#include "organfit/fitting/global_map.h"

#include <Eigen/Eigenvalues>
#include <Eigen/LU>
#include <algorithm>
#include <array>
#include <cmath>

#include "mapped_samples.h"

namespace organfit::fitting {

Eigen::Vector3d QuadraticShears::apply(const Eigen::Vector3d& q) const {
  Eigen::Vector3d u = q - centre;
  u.x() += c(0) * u.y() * u.y() + c(1) * u.z() * u.z() + c(2) * u.y() * u.z();
  u.y() += c(3) * u.x() * u.x() + c(4) * u.z() * u.z() + c(5) * u.x() * u.z();
  u.z() += c(6) * u.x() * u.x() + c(7) * u.y() * u.y() + c(8) * u.x() * u.y();
  u.y() += c(9) * u.x() * u.x() + c(10) * u.z() * u.z() + c(11) * u.x() * u.z();
  u.x() += c(12) * u.y() * u.y() + c(13) * u.z() * u.z() + c(14) * u.y() * u.z();
  return centre + u;
}

Eigen::Vector3d QuadraticShears::inverse(const Eigen::Vector3d& q) const {
  Eigen::Vector3d u = q - centre;  // undo the shears in reverse order
  u.x() -= c(12) * u.y() * u.y() + c(13) * u.z() * u.z() + c(14) * u.y() * u.z();
  u.y() -= c(9) * u.x() * u.x() + c(10) * u.z() * u.z() + c(11) * u.x() * u.z();
  u.z() -= c(6) * u.x() * u.x() + c(7) * u.y() * u.y() + c(8) * u.x() * u.y();
  u.y() -= c(3) * u.x() * u.x() + c(4) * u.z() * u.z() + c(5) * u.x() * u.z();
  u.x() -= c(0) * u.y() * u.y() + c(1) * u.z() * u.z() + c(2) * u.y() * u.z();
  return centre + u;
}

namespace {
/// The two axes other than `a`, in order.
std::pair<int, int> other_axes(int a) {
  return {a == 0 ? 1 : 0, a == 2 ? 1 : 2};
}
}  // namespace

ShearFields ShearFields::over(const Eigen::Vector3d& box_min_mm, const Eigen::Vector3d& box_max_mm,
                              double sigma_mm) {
  ShearFields f;
  f.sigma_mm = sigma_mm;
  if (!(sigma_mm > 0)) return f;
  for (int a = 0; a < 3; ++a) {  // centred on the box, reaching one spacing beyond it
    const double span = box_max_mm(a) - box_min_mm(a) + 2 * sigma_mm;
    f.count(a) = 1 + static_cast<int>(std::ceil(std::max(0.0, span) / sigma_mm));
    f.origin_mm(a) = 0.5 * (box_min_mm(a) + box_max_mm(a)) - 0.5 * (f.count(a) - 1) * sigma_mm;
  }
  f.weights = Eigen::VectorXd::Zero(3 * f.block());
  return f;
}

int ShearFields::block() const {
  int most = 0;
  for (int a = 0; a < 3; ++a) {
    const auto [b, c] = other_axes(a);
    most = std::max(most, count(b) * count(c));
  }
  return most;
}

namespace {
/// Calls visit(index, value) for each bump of field `a` of `f` at q at least 1e-6 (the
/// centres within 5.3 sigmas of q's other two coordinates), in a fixed order.
template <class Visit>
void for_each_bump(const ShearFields& f, int a, const Eigen::Vector3d& q, Visit&& visit) {
  if (!(f.sigma_mm > 0)) return;
  const auto [b, c] = other_axes(a);
  const double reach = 5.3;  // sigmas: exp(-5.3^2 / 2) < 1e-6
  const double ub = (q(b) - f.origin_mm(b)) / f.sigma_mm, uc = (q(c) - f.origin_mm(c)) / f.sigma_mm;
  const int i0 = std::max(0, static_cast<int>(std::ceil(ub - reach))),
            i1 = std::min(f.count(b) - 1, static_cast<int>(std::floor(ub + reach)));
  const int j0 = std::max(0, static_cast<int>(std::ceil(uc - reach))),
            j1 = std::min(f.count(c) - 1, static_cast<int>(std::floor(uc + reach)));
  if (i1 - i0 >= 16) return;  // cannot happen: 2 x 5.3 sigmas span at most 11 centres
  // The Gaussian is separable: one exp per row and per column, not per bump.
  double along_b[16];
  for (int i = i0; i <= i1; ++i)
    along_b[i - i0] = std::exp(-0.5 * (ub - i) * (ub - i));
  const int first = a * f.block();
  for (int j = j0; j <= j1; ++j) {
    const double along_c = std::exp(-0.5 * (uc - j) * (uc - j));
    for (int i = i0; i <= i1; ++i) {
      const double e = along_b[i - i0] * along_c;
      if (e >= 1e-6) visit(first + i + f.count(b) * j, e);
    }
  }
}
}  // namespace

void ShearFields::bumps(int a, const Eigen::Vector3d& q,
                        std::vector<std::pair<int, double>>& out) const {
  out.clear();
  for_each_bump(*this, a, q, [&](int index, double value) { out.emplace_back(index, value); });
}

double ShearFields::field(int a, const Eigen::Vector3d& q) const {
  // Summed as visited, without a list: it is called for every lattice site of a re-fill
  // and every voxel an evaluation asks about.
  double f = 0;
  if (weights.size() == 0) return f;
  for_each_bump(*this, a, q, [&](int index, double value) { f += weights(index) * value; });
  return f;
}

Eigen::Vector3d ShearFields::apply(const Eigen::Vector3d& q) const {
  Eigen::Vector3d u = q;
  if (weights.size() == 0) return u;
  for (int a = 0; a < 3; ++a)
    u(a) += field(a, u);
  return u;
}

Eigen::Vector3d ShearFields::inverse(const Eigen::Vector3d& q) const {
  Eigen::Vector3d u = q;  // undo the fields in reverse order
  if (weights.size() == 0) return u;
  for (int a = 2; a >= 0; --a)
    u(a) -= field(a, u);
  return u;
}

Eigen::Vector3d GlobalMap::inverse(const Eigen::Vector3d& q) const {
  return inverse(q, affine.a.inverse());
}

namespace {
/// sup over x of sum_i |t|^p exp(-t^2 / 2) ... for the sums of a row of unit bumps and of
/// their derivatives (t = x - i): [0] sum_i g(t), [1] sum_i |g'(t)| = |t| g(t), [2] sum_i
/// |g''(t)| = |t^2 - 1| g(t). Sampled over a period at 1/1000 and raised by 0.01, more
/// than the sampling can miss (the sums' slopes are below 3).
const std::array<double, 3>& bump_sum_bounds() {
  static const std::array<double, 3> bounds = [] {
    std::array<double, 3> b{0, 0, 0};
    for (int s = 0; s <= 1000; ++s) {
      const double x = s / 1000.0;
      std::array<double, 3> sum{0, 0, 0};
      for (int i = -12; i <= 12; ++i) {
        const double t = x - i, e = std::exp(-0.5 * t * t);
        sum[0] += e, sum[1] += std::abs(t) * e, sum[2] += std::abs(t * t - 1) * e;
      }
      for (int k = 0; k < 3; ++k)
        b[k] = std::max(b[k], sum[k] + 0.01);
    }
    return b;
  }();
  return bounds;
}

/// The largest singular value of a shear I - e_a g^T whose gradient g (of length `g`) is
/// normal to e_a: (g + sqrt(g^2 + 4)) / 2, about 1 + g / 2 for a small one.
double shear_stretch(double g) {
  return 0.5 * (g + std::sqrt(g * g + 4));
}

/// What the bumps ShearFields leaves out (each below 1e-6) sum to at most, per unit
/// weight: about 2 pi e^(-5.3^2 / 2) = 6e-6 over the plane; 1e-4 to spare.
constexpr double kLeftOutBumps = 1e-4;
}  // namespace

double ShearFields::largest_weight(int a) const {
  return weights.size() == 0 ? 0.0 : weights.segment(a * block(), block()).cwiseAbs().maxCoeff();
}

double ShearFields::largest_gradient(int a, const geometry::Aabb& box) const {
  if (empty()) return 0;
  const auto [b, c] = other_axes(a);
  const double w = largest_weight(a);
  if (w == 0) return 0;
  const auto& sums = bump_sum_bounds();
  // |grad f_a| sampled at most delta = sigma / 8 apart over the box's projection, every
  // bump counted; between samples it can be larger by at most the Hessian's norm (bounded
  // from the largest weight) times the distance to the nearest sample, delta / sqrt(2).
  const double hessian = w / (sigma_mm * sigma_mm) *
                         std::sqrt(2 * std::pow(sums[2] * sums[0], 2) + 2 * std::pow(sums[1], 4));
  const double delta = sigma_mm / 8;
  const double span_b = std::max(0.0, box.max_mm[b] - box.min_mm[b]),
               span_c = std::max(0.0, box.max_mm[c] - box.min_mm[c]);
  const int nb = 1 + static_cast<int>(std::ceil(span_b / delta)),
            nc = 1 + static_cast<int>(std::ceil(span_c / delta));
  if (1.0 * nb * nc > 1e6)  // a box far larger than the fields: the bound from the weights
    return std::sqrt(2.0) * w * sums[1] * sums[0] / sigma_mm;
  double largest = 0;
#pragma omp parallel for collapse(2) reduction(max : largest) schedule(static)
  for (int jc = 0; jc < nc; ++jc)
    for (int jb = 0; jb < nb; ++jb) {
      const double ub = (box.min_mm[b] + (nb > 1 ? span_b * jb / (nb - 1) : 0) - origin_mm[b]) /
                        sigma_mm,
                   uc = (box.min_mm[c] + (nc > 1 ? span_c * jc / (nc - 1) : 0) - origin_mm[c]) /
                        sigma_mm;
      double gb = 0, gc = 0;
      const int i0 = std::max(0, static_cast<int>(std::ceil(ub - 9))),
                i1 = std::min(count(b) - 1, static_cast<int>(std::floor(ub + 9)));
      const int j0 = std::max(0, static_cast<int>(std::ceil(uc - 9))),
                j1 = std::min(count(c) - 1, static_cast<int>(std::floor(uc + 9)));
      double along_b[19];
      for (int i = i0; i <= i1; ++i)
        along_b[i - i0] = std::exp(-0.5 * (ub - i) * (ub - i));
      for (int j = j0; j <= j1; ++j) {
        const double tc = uc - j, ec = std::exp(-0.5 * tc * tc);
        for (int i = i0; i <= i1; ++i) {
          const double tb = ub - i, eb = along_b[i - i0];
          const double wij = weights(a * block() + i + count(b) * j);
          gb -= wij * tb * eb * ec, gc -= wij * eb * tc * ec;
        }
      }
      largest = std::max(largest, std::hypot(gb, gc) / sigma_mm);
    }
  // Bumps beyond 9 sigmas (each below e^-40) are not worth a term; 1e-12 covers them.
  return largest + hessian * delta / std::sqrt(2.0) + 1e-12 * w;
}

StretchBound GlobalMap::inverse_stretch(const geometry::Aabb& box) const {
  StretchBound out;
  Eigen::Vector3d lo = box.min_mm, hi = box.max_mm;
  double stretch = 1, slack = 0;
  // The fields, undone z, y, x: each step q_a -= f_a(q_b, q_c) is a shear, Jacobian I - e_a
  // grad f_a^T (shear_stretch), and moves q_a by at most |f_a|.
  if (!fields.empty()) {
    const double sum0 = bump_sum_bounds()[0];
    for (int a = 2; a >= 0; --a) {
      const double w = fields.largest_weight(a);
      stretch *= shear_stretch(fields.largest_gradient(a, geometry::Aabb{lo, hi}));
      const double move = w * (sum0 * sum0 + kLeftOutBumps);
      lo[a] -= move, hi[a] += move;
      slack += w * kLeftOutBumps;
    }
  }
  // The shears, undone in reverse order: each moves one coordinate of u = q - centre by a
  // quadratic of the other two, whose gradient and size grow with |u| (bounded per axis,
  // grown by each step's move).
  Eigen::Vector3d u = (lo - shears.centre).cwiseAbs().cwiseMax((hi - shears.centre).cwiseAbs());
  const auto& c = shears.c;
  auto undo = [&](int a, int b, int d, int first) {  // q_a -= c0 u_b^2 + c1 u_d^2 + c2 u_b u_d
    const double c0 = std::abs(c(first)), c1 = std::abs(c(first + 1)), c2 = std::abs(c(first + 2));
    stretch *= shear_stretch(std::hypot(2 * c0 * u[b] + c2 * u[d], 2 * c1 * u[d] + c2 * u[b]));
    u[a] += c0 * u[b] * u[b] + c1 * u[d] * u[d] + c2 * u[b] * u[d];
  };
  undo(0, 1, 2, 12), undo(1, 0, 2, 9), undo(2, 0, 1, 6), undo(1, 0, 2, 3), undo(0, 1, 2, 0);
  // The affine part: a^-1's largest singular value.
  Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> ata;
  ata.computeDirect(affine.a.transpose() * affine.a, Eigen::EigenvaluesOnly);
  stretch /= std::sqrt(ata.eigenvalues()(0));
  out.stretch = stretch;
  // A left-out bump's error in one step is carried through the steps after it, each
  // stretching by at most the whole bound.
  out.slack_mm = stretch * slack;
  return out;
}

SurfaceSamples map_surface(const GlobalMap& map, const SurfaceSamples& surface) {
  SurfaceSamples out;
  out.points.resize(3, surface.points.cols());
  out.normals.resize(3, surface.points.cols());
  const double h = 1e-3;  // mm: the shears' second derivatives are ~1/100 mm^-1
  for (Eigen::Index j = 0; j < surface.points.cols(); ++j) {
    const Eigen::Vector3d s = surface.points.col(j);
    Eigen::Matrix3d jacobian;
    for (int c = 0; c < 3; ++c) {
      const Eigen::Vector3d e = h * Eigen::Vector3d::Unit(c);
      jacobian.col(c) = (map.apply(s + e) - map.apply(s - e)) / (2 * h);
    }
    out.points.col(j) = map.apply(s);
    out.normals.col(j) = (jacobian.inverse().transpose() * surface.normals.col(j)).normalized();
  }
  return out;
}

double shape_change_mm(const GlobalMap& map, const SurfaceSamples& surface) {
  return shape_change_of(map_samples(map, surface).full, surface.points);
}

LargestMoves largest_moves(const GlobalMap& map, const SurfaceSamples& surface) {
  return largest_moves_of(map_samples(map, surface));
}

}  // namespace organfit::fitting
