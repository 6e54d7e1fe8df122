#include "organfit/fitting/global_map.h"

#include <Eigen/Eigenvalues>
#include <Eigen/Geometry>
#include <Eigen/LU>
#include <Eigen/SVD>
#include <algorithm>
#include <array>
#include <cmath>

#include "bump_sums.h"
#include "central_differences.h"
#include "mapped_samples.h"
#include "organfit/fitting/shear_field_table.h"
#include "other_axes.h"

namespace organfit::fitting {

using detail::other_axes;

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

int ShearFields::weight_index(int a, int i, int j) const {
  return a * block() + i + count(other_axes(a).first) * j;
}

Eigen::Map<const Eigen::MatrixXd> ShearFields::heights(int a) const {
  const auto [b, c] = other_axes(a);
  return {weights.data() + weight_index(a, 0, 0), count(b), count(c)};
}

namespace {
/// g(t0 - k) = exp(-(t0 - k)^2 / 2) for k = 0 .. n - 1, into g: from the centre nearest
/// the peak (its value by exp, exactly 1 on it) outwards, g(t -+ 1) = g(t) exp(+-t - 1/2),
/// the factor shrinking by 1/e a centre: three exps a row instead of one a centre.
void gaussian_row(double t0, int n, double* g) {
  if (n <= 0) return;
  const double inv_e = std::exp(-1.0);
  const int peak = static_cast<int>(std::clamp(std::round(t0), 0.0, static_cast<double>(n - 1)));
  const double t = t0 - peak;
  g[peak] = std::exp(-0.5 * t * t);
  double factor = std::exp(t - 0.5);  // towards larger k: t falls
  for (int k = peak + 1; k < n; ++k, factor *= inv_e)
    g[k] = g[k - 1] * factor;
  factor = std::exp(-t - 0.5);  // towards smaller k: t rises
  for (int k = peak - 1; k >= 0; --k, factor *= inv_e)
    g[k] = g[k + 1] * factor;
}

/// A bump below this (of unit height) is left out of a field.
constexpr double kLeastBump = 1e-6;

/// The bump centres along one axis within 5.3 sigmas of coordinate x (exp(-5.3^2 / 2) <
/// kLeastBump): centres i0..i1, centre i's Gaussian value g[i - i0]. Empty (i0 > i1)
/// without a grid. A field's bumps are products of a row along each of its two other axes
/// (the Gaussian is separable), and a row depends on its axis and coordinate alone: apply
/// and inverse share the rows of a coordinate the fields before left unchanged.
struct BumpRow {
  int i0 = 0, i1 = -1;
  double g[16];
  BumpRow(const ShearFields& f, int axis, double x) {
    if (!(f.sigma_mm > 0)) return;
    const double reach = 5.3;
    const double u = (x - f.origin_mm(axis)) / f.sigma_mm;
    i0 = std::max(0, static_cast<int>(std::ceil(u - reach)));
    i1 = std::min(f.count(axis) - 1, static_cast<int>(std::floor(u + reach)));
    if (i1 - i0 >= 16) {  // cannot be: 2 x 5.3 sigmas span 11 centres
      i1 = i0 - 1;
      return;
    }
    gaussian_row(u - i0, i1 - i0 + 1, g);
  }
  bool empty() const { return i0 > i1; }
};

/// The bumps of field `a` of `f` about q: rows i along axis b (along_b), columns j along
/// c (along_c), bump (i, j)'s value along_b.g[i - i0] * along_c.g[j - j0] and weight
/// index first + i + stride * j.
struct BumpWindow {
  BumpRow along_b, along_c;
  int first, stride;
  BumpWindow(const ShearFields& f, int a, const Eigen::Vector3d& q)
      : along_b(f, other_axes(a).first, q(other_axes(a).first)),
        along_c(f, other_axes(a).second, q(other_axes(a).second)),
        first(f.weight_index(a, 0, 0)),
        stride(f.weight_index(a, 0, 1) - first) {}
  bool empty() const { return along_b.empty() || along_c.empty(); }
};

/// Calls visit(index, value) for each bump of field `a` of `f` at q at least kLeastBump,
/// in a fixed order.
template <class Visit>
void for_each_bump(const ShearFields& f, int a, const Eigen::Vector3d& q, Visit&& visit) {
  const BumpWindow w(f, a, q);
  if (w.empty()) return;
  const BumpRow &rb = w.along_b, &rc = w.along_c;
  for (int j = rc.i0; j <= rc.i1; ++j)
    for (int i = rb.i0; i <= rb.i1; ++i) {
      const double e = rb.g[i - rb.i0] * rc.g[j - rc.i0];
      if (e >= kLeastBump) visit(w.first + i + w.stride * j, e);
    }
}

/// Field `a` of `f` from its two rows (b then c, other_axes' order): the bumps
/// for_each_bump visits, without a list (it is called for every lattice site of a re-fill
/// and every voxel an evaluation asks about) and a column at a time: along a column the
/// values are unimodal, so those at least kLeastBump are a run, summed as one dot product.
double field_of(const ShearFields& f, int a, const BumpRow& rb, const BumpRow& rc) {
  double sum_all = 0;
  if (f.weights.size() == 0 || rb.empty() || rc.empty()) return sum_all;
  const auto heights = f.heights(a);
  for (int j = rc.i0; j <= rc.i1; ++j) {
    const double c = rc.g[j - rc.i0];
    int lo = rb.i0, hi = rb.i1;
    while (lo <= hi && rb.g[lo - rb.i0] * c < kLeastBump)
      ++lo;
    while (hi >= lo && rb.g[hi - rb.i0] * c < kLeastBump)
      --hi;
    const double* weight = heights.col(j).data();
    double sum = 0;
    for (int i = lo; i <= hi; ++i)
      sum += weight[i] * rb.g[i - rb.i0];
    sum_all += c * sum;
  }
  return sum_all;
}
}  // namespace

void ShearFields::bumps(int a, const Eigen::Vector3d& q,
                        std::vector<std::pair<int, double>>& out) const {
  out.clear();
  for_each_bump(*this, a, q, [&](int index, double value) { out.emplace_back(index, value); });
}

double ShearFields::field(int a, const Eigen::Vector3d& q) const {
  if (weights.size() == 0) return 0;
  const auto [b, c] = other_axes(a);
  return field_of(*this, a, BumpRow(*this, b, q(b)), BumpRow(*this, c, q(c)));
}

Eigen::Vector3d ShearFields::apply(const Eigen::Vector3d& q) const {
  Eigen::Vector3d u = q;  // the fields x, y, z, each on the coordinates the ones before left
  if (weights.size() == 0) return u;
  const BumpRow y(*this, 1, u(1)), z(*this, 2, u(2));
  u(0) += field_of(*this, 0, y, z);
  const BumpRow x(*this, 0, u(0));
  u(1) += field_of(*this, 1, x, z);
  u(2) += field_of(*this, 2, x, BumpRow(*this, 1, u(1)));
  return u;
}

Eigen::Vector3d ShearFields::inverse(const Eigen::Vector3d& q) const {
  Eigen::Vector3d u = q;  // undo the fields in reverse order
  if (weights.size() == 0) return u;
  const BumpRow x(*this, 0, u(0)), y(*this, 1, u(1));
  u(2) -= field_of(*this, 2, x, y);
  const BumpRow z(*this, 2, u(2));
  u(1) -= field_of(*this, 1, x, z);
  u(0) -= field_of(*this, 0, BumpRow(*this, 1, u(1)), z);
  return u;
}

namespace {
/// The uniform cubic B-spline and its first two derivatives at t.
double bspline(double t) {
  t = std::abs(t);
  return t < 1 ? (4 - 6 * t * t + 3 * t * t * t) / 6 : t < 2 ? (2 - t) * (2 - t) * (2 - t) / 6 : 0;
}
double bspline_slope(double t) {
  const double a = std::abs(t);
  return a < 1 ? -2 * t + 1.5 * t * a : a < 2 ? (t > 0 ? -1 : 1) * (2 - a) * (2 - a) / 2 : 0;
}

/// The B-spline's values and slopes along each axis at the 4 nodes about a point, nodes
/// first[a] + i (zero for nodes beyond the grid); false without a grid or a finite point.
struct NodeWeights {
  int first[3];
  double value[3][4], slope[3][4];
};
bool node_weights(const IncompressibleFlow& f, const Eigen::Vector3d& q, NodeWeights& w) {
  if (!(f.sigma_mm > 0) || f.potentials.size() == 0) return false;  // no grid
  const Eigen::Vector3d u = (q - f.origin_mm) / f.sigma_mm;
  if (!u.allFinite()) return false;
  for (int a = 0; a < 3; ++a) {
    w.first[a] = static_cast<int>(std::floor(u(a))) - 1;
    for (int i = 0; i < 4; ++i) {
      const int node = w.first[a] + i;
      const bool on = node >= 0 && node < f.count(a);
      w.value[a][i] = on ? bspline(u(a) - node) : 0;
      w.slope[a][i] = on ? bspline_slope(u(a) - node) : 0;
    }
  }
  return true;
}
}  // namespace

IncompressibleFlow IncompressibleFlow::over(const Eigen::Vector3d& box_min_mm,
                                            const Eigen::Vector3d& box_max_mm, double sigma_mm) {
  IncompressibleFlow f;
  f.sigma_mm = sigma_mm;
  if (!(sigma_mm > 0)) return f;
  for (int a = 0; a < 3; ++a) {  // centred on the box, two spacings beyond it
    const double span = box_max_mm(a) - box_min_mm(a) + 4 * sigma_mm;
    f.count(a) = 1 + static_cast<int>(std::ceil(std::max(0.0, span) / sigma_mm));
    f.origin_mm(a) = 0.5 * (box_min_mm(a) + box_max_mm(a)) - 0.5 * (f.count(a) - 1) * sigma_mm;
  }
  f.potentials = Eigen::VectorXd::Zero(3 * f.count.prod());
  return f;
}

void IncompressibleFlow::basis_gradients(const Eigen::Vector3d& q,
                                         std::vector<std::pair<int, Eigen::Vector3d>>& out) const {
  out.clear();
  NodeWeights nw;
  if (!node_weights(*this, q, nw)) return;
  const auto& [first, value, slope] = nw;
  for (int k = 0; k < 4; ++k)
    for (int j = 0; j < 4; ++j)
      for (int i = 0; i < 4; ++i) {
        const double bx = value[0][i], by = value[1][j], bz = value[2][k];
        const Eigen::Vector3d g(slope[0][i] * by * bz, bx * slope[1][j] * bz,
                                bx * by * slope[2][k]);
        if (g.isZero(0)) continue;
        out.emplace_back(first[0] + i + count(0) * (first[1] + j + count(1) * (first[2] + k)), g);
      }
}

Eigen::Vector3d IncompressibleFlow::velocity(const Eigen::Vector3d& q) const {
  // sum_n g_n x a_n over the 4 x 4 x 4 nodes about q, g_n = (B'BB, BB'B, BBB'), summed along
  // x first (no list: it is called 16 times for each point the flow moves).
  Eigen::Vector3d v = Eigen::Vector3d::Zero();
  NodeWeights nw;
  if (!node_weights(*this, q, nw)) return v;
  const auto& [first, value, slope] = nw;
  const double* a = potentials.data();
  for (int k = 0; k < 4; ++k) {
    if (value[2][k] == 0 && slope[2][k] == 0) continue;
    for (int j = 0; j < 4; ++j) {
      if (value[1][j] == 0 && slope[1][j] == 0) continue;
      // Along x: s = sum B'_i a_i, w = sum B_i a_i (each a 3-vector).
      Eigen::Vector3d s = Eigen::Vector3d::Zero(), w = Eigen::Vector3d::Zero();
      const long long row =
          3LL * (first[0] + count(0) * (first[1] + j + count(1) * (first[2] + k)));
      for (int i = 0; i < 4; ++i) {
        if (value[0][i] == 0 && slope[0][i] == 0) continue;
        const Eigen::Vector3d an(a[row + 3 * i], a[row + 3 * i + 1], a[row + 3 * i + 2]);
        s += slope[0][i] * an, w += value[0][i] * an;
      }
      // g x a summed: (B'_x B_y B_z, B_x B'_y B_z, B_x B_y B'_z) x a.
      const double by = value[1][j], dy = slope[1][j], bz = value[2][k], dz = slope[2][k];
      const Eigen::Vector3d gx = by * bz * s, gy = dy * bz * w, gz = by * dz * w;
      // sum (e_x c_x + e_y c_y + e_z c_z) x a, each part a cross product with a unit axis.
      v += Eigen::Vector3d(0, -gx.z(), gx.y()) + Eigen::Vector3d(gy.z(), 0, -gy.x()) +
           Eigen::Vector3d(-gz.y(), gz.x(), 0);
    }
  }
  return v;
}

namespace {
/// The flow of `sign` x v over unit time from q, RK4 in kSteps steps.
Eigen::Vector3d integrate(const IncompressibleFlow& f, Eigen::Vector3d q, double sign) {
  const double h = sign / IncompressibleFlow::kSteps;
  for (int s = 0; s < IncompressibleFlow::kSteps; ++s) {
    const Eigen::Vector3d k1 = f.velocity(q), k2 = f.velocity(q + 0.5 * h * k1),
                          k3 = f.velocity(q + 0.5 * h * k2), k4 = f.velocity(q + h * k3);
    q += h / 6 * (k1 + 2 * k2 + 2 * k3 + k4);
  }
  return q;
}
}  // namespace

// Without a grid the identity; all-zero potentials integrate to q exactly, so the points
// a map moves are not each charged a scan of the potentials (empty()).
Eigen::Vector3d IncompressibleFlow::apply(const Eigen::Vector3d& q) const {
  return sigma_mm > 0 && potentials.size() > 0 ? integrate(*this, q, 1) : q;
}

Eigen::Vector3d IncompressibleFlow::inverse(const Eigen::Vector3d& q) const {
  return sigma_mm > 0 && potentials.size() > 0 ? integrate(*this, q, -1) : q;
}

namespace {
/// The largest |first difference| of each potential component along each axis, and of
/// each second difference (j, l), over the nodes and their neighbours beyond the grid (zero
/// there). A derivative of a B-spline expansion is the expansion of the differences in
/// lower B-splines, non-negative and summing to one, so d_j psi_c is at most m1[j][c] and
/// d_j d_l psi_c at most m2[j][l][c] / sigma everywhere (psi = sigma sum_n a_n B).
struct PotentialDifferences {
  double m1[3][3] = {}, m2[3][3][3] = {};
};
PotentialDifferences potential_differences(const IncompressibleFlow& f) {
  PotentialDifferences d;
  const Eigen::Vector3i n = f.count;
  auto at = [&](int i, int j, int k, int c) {
    if (i < 0 || j < 0 || k < 0 || i >= n(0) || j >= n(1) || k >= n(2)) return 0.0;
    return f.potentials(3 * (i + n(0) * (j + n(1) * k)) + c);
  };
  for (int k = -1; k <= n(2); ++k)
    for (int j = -1; j <= n(1); ++j)
      for (int i = -1; i <= n(0); ++i)
        for (int c = 0; c < 3; ++c) {
          const int at0[3] = {i, j, k};
          auto shifted = [&](int ax, int by, int ax2 = 0, int by2 = 0) {
            int p[3] = {at0[0], at0[1], at0[2]};
            p[ax] += by, p[ax2] += by2;
            return at(p[0], p[1], p[2], c);
          };
          const double a = at(i, j, k, c);
          for (int x = 0; x < 3; ++x) {
            d.m1[x][c] = std::max(d.m1[x][c], std::abs(shifted(x, 1) - a));
            const double second = shifted(x, 1) - 2 * a + shifted(x, -1);
            d.m2[x][x][c] = std::max(d.m2[x][x][c], std::abs(second));
            for (int y = x + 1; y < 3; ++y) {
              const double mixed = shifted(x, 1, y, 1) - shifted(x, 1) - shifted(y, 1) + a;
              d.m2[x][y][c] = d.m2[y][x][c] = std::max(d.m2[x][y][c], std::abs(mixed));
            }
          }
        }
  return d;
}
}  // namespace

IncompressibleFlow::Bounds IncompressibleFlow::bounds() const {
  if (empty()) return {};
  const PotentialDifferences d = potential_differences(*this);
  // v = curl psi: v_i = d_j psi_k - d_k psi_j ((i, j, k) cyclic), and its gradient
  // d_l v_i = d_l d_j psi_k - d_l d_k psi_j; the spectral norm at most the Frobenius one.
  double speed_sq = 0, gradient_sq = 0;
  for (int i = 0; i < 3; ++i) {
    const int j = (i + 1) % 3, k = (i + 2) % 3;
    speed_sq += (d.m1[j][k] + d.m1[k][j]) * (d.m1[j][k] + d.m1[k][j]);
    for (int l = 0; l < 3; ++l) {
      const double b = d.m2[l][j][k] + d.m2[l][k][j];
      gradient_sq += b * b;
    }
  }
  return {std::sqrt(speed_sq), std::sqrt(gradient_sq) / sigma_mm};
}

double IncompressibleFlow::stiffness_per_field_stiffness() {
  // A component of v = sum_n g_n x a_n, the a_n independent of unit variance, has variance
  // (2/3) sum_n |g_n|^2, averaged over a cell 3 (int B'^2)(int B^2)^2; a field's move has
  // sum_j bump_j^2 per unit height variance, (int exp(-t^2) dt)^2 = pi. Without this ratio
  // the same stiffness held the flow ten times harder than the fields.
  static const double scale = [] {
    double b2 = 0, d2 = 0;  // int B^2, int B'^2 by the midpoint rule over [-2, 2]
    const int n = 4000;
    for (int i = 0; i < n; ++i) {
      const double t = -2 + 4.0 * (i + 0.5) / n, b = bspline(t), d = bspline_slope(t);
      b2 += b * b * 4.0 / n, d2 += d * d * 4.0 / n;
    }
    return (2.0 / 3.0) * 3 * d2 * b2 * b2 / M_PI;
  }();
  return scale;
}

Eigen::Vector3d GlobalMap::inverse(const Eigen::Vector3d& q) const {
  return inverse(q, affine.a.inverse());
}

Eigen::Vector3d GlobalMap::apply(const Eigen::Vector3d& p, const ShearFieldTable& table) const {
  return flow.apply(table.apply(shears.apply(affine.a * p + affine.t)));
}

Eigen::Vector3d GlobalMap::inverse(const Eigen::Vector3d& q, const Eigen::Matrix3d& a_inverse,
                                   const ShearFieldTable& table) const {
  return a_inverse * (shears.inverse(table.inverse(flow.inverse(q))) - affine.t);
}

namespace detail {
const std::array<double, 5>& bump_sum_bounds() {
  static const std::array<double, 5> bounds = [] {
    std::array<double, 5> b{0, 0, 0, 0, 0};
    for (int s = 0; s <= 1000; ++s) {
      const double x = s / 1000.0;
      std::array<double, 5> sum{0, 0, 0, 0, 0};
      for (int i = -12; i <= 12; ++i) {
        const double t = x - i, e = std::exp(-0.5 * t * t), t2 = t * t;
        sum[0] += e, sum[1] += std::abs(t) * e, sum[2] += std::abs(t2 - 1) * e;
        sum[3] += std::abs(t * (t2 - 3)) * e, sum[4] += std::abs(t2 * t2 - 6 * t2 + 3) * e;
      }
      for (int k = 0; k < 5; ++k)
        b[static_cast<size_t>(k)] =
            std::max(b[static_cast<size_t>(k)], sum[static_cast<size_t>(k)] + 0.01);
    }
    return b;
  }();
  return bounds;
}
}  // namespace detail

namespace {
using detail::bump_sum_bounds;

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
  return weights.size() == 0 ? 0.0 : heights(a).cwiseAbs().maxCoeff();
}

double ShearFields::largest_gradient(int a, const geometry::Aabb& box) const {
  if (empty()) return 0;
  // Plain ints, not a structured binding: the loop's OpenMP region below reads them, and
  // clang (the fuzzing build) cannot capture a binding before C++20.
  const int b = other_axes(a).first, c = other_axes(a).second;
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
  const auto field_heights = heights(a);
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
          const double wij = field_heights(i, j);
          gb -= wij * tb * eb * ec, gc -= wij * eb * tc * ec;
        }
      }
      largest = std::max(largest, std::hypot(gb, gc) / sigma_mm);
    }
  // Bumps beyond 9 sigmas (each below e^-40) are not worth a term; 1e-12 covers them.
  return largest + hessian * delta / std::sqrt(2.0) + 1e-12 * w;
}

StretchBound GlobalMap::inverse_stretch(const geometry::Aabb& box,
                                        const FieldEvaluationError& evaluation) const {
  StretchBound out;
  Eigen::Vector3d lo = box.min_mm, hi = box.max_mm;
  double stretch = 1, slack = 0;
  // The flow, undone first: RK4's step on a field whose gradient is at most L stretches by
  // at most 1 + hL + ... + (hL)^4 / 24 <= exp(hL), the whole flow by exp(L); it moves a
  // point by at most the largest speed.
  if (!flow.empty()) {
    const IncompressibleFlow::Bounds b = flow.bounds();
    stretch *= std::exp(b.velocity_gradient);
    lo.array() -= b.speed_mm, hi.array() += b.speed_mm;
  }
  // The fields, undone z, y, x: each step q_a -= f_a(q_b, q_c) is a shear, Jacobian I - e_a
  // grad f_a^T (shear_stretch), and moves q_a by at most |f_a|.
  if (!fields.empty()) {
    const double sum0 = bump_sum_bounds()[0];
    for (int a = 2; a >= 0; --a) {
      const double w = fields.largest_weight(a);
      stretch *= shear_stretch(fields.largest_gradient(a, geometry::Aabb{lo, hi}) +
                               evaluation.gradient[static_cast<size_t>(a)]);
      const double move =
          w * (sum0 * sum0 + kLeftOutBumps) + evaluation.value_mm[static_cast<size_t>(a)];
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
  out.keys = surface.keys;                   // the same samples, moved
  const double h = 1e-3;                     // mm: the shears' second derivatives are ~1/100 mm^-1
  const ShearFieldTable fields(map.fields);  // 7 maps a sample: a lung's 630,000
#pragma omp parallel for schedule(static)
  for (Eigen::Index j = 0; j < surface.points.cols(); ++j) {
    const Eigen::Vector3d s = surface.points.col(j);
    const Eigen::Matrix3d jacobian = detail::central_jacobian(
        [&](const Eigen::Vector3d& p) { return map.apply(p, fields); }, s, h);
    out.points.col(j) = map.apply(s, fields);
    out.normals.col(j) = (jacobian.inverse().transpose() * surface.normals.col(j)).normalized();
  }
  return out;
}

double shape_change_mm(const GlobalMap& map, const SurfaceSamples& surface) {
  return shape_change_of(map_samples(map, surface).full, surface.points);
}

LargestMoves largest_moves(const GlobalMap& map, const SurfaceSamples& surface) {
  return map_samples(map, surface).moves;
}

GlobalMap towards_identity(const GlobalMap& map, double c, const Eigen::Vector3d& centre) {
  if (c >= 1) return map;
  GlobalMap out = map;
  if (c <= 0) {  // the identity exactly (GlobalMap::identity() holds), its metadata kept
    out.affine.a.setIdentity();
    out.affine.t.setZero();
    out.shears.c.setZero();
    out.fields.weights.setZero();
    out.flow.potentials.setZero();
    return out;
  }
  // a = R S (polar decomposition: a = U s V^T, R = U V^T, S = V s V^T), det R = det S = 1.
  const Eigen::JacobiSVD<Eigen::Matrix3d> svd(map.affine.a,
                                              Eigen::ComputeFullU | Eigen::ComputeFullV);
  const Eigen::Matrix3d r = svd.matrixU() * svd.matrixV().transpose();
  const Eigen::AngleAxisd turn(r);
  const Eigen::Vector3d stretches = svd.singularValues().array().pow(c);
  out.affine.a = Eigen::AngleAxisd(c * turn.angle(), turn.axis()).toRotationMatrix() *
                 svd.matrixV() * stretches.asDiagonal() * svd.matrixV().transpose();
  const Eigen::Vector3d move = map.affine.a * centre + map.affine.t - centre;
  out.affine.t = centre + c * move - out.affine.a * centre;
  // The other parts act where the affine part puts the organ: moved with its centre.
  const Eigen::Vector3d moved_by = (c - 1) * move;
  out.shears.centre += moved_by;
  out.fields.origin_mm += moved_by;
  out.flow.origin_mm += moved_by;
  out.shears.c *= c;
  out.fields.weights *= c;
  out.flow.potentials *= c;
  return out;
}

}  // namespace organfit::fitting
