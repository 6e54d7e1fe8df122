#include "organfit/fitting/shear_field_table.h"

#include <Eigen/Dense>
#include <cmath>
#include <tuple>

#include "bump_sums.h"
#include "other_axes.h"

namespace organfit::fitting {

namespace {
/// The plane's nodes along one axis: Gaussian values g(t) and h times their derivatives
/// in mm, -t g(t) h / sigma, at the nodes (rows) for each bump centre (columns); t the
/// node's distance from the centre in sigmas.
void node_rows(int centres, int nodes, int per_sigma, Eigen::MatrixXd& value,
               Eigen::MatrixXd& slope) {
  const double per = per_sigma;
  value.resize(nodes, centres), slope.resize(nodes, centres);
  for (int p = 0; p < nodes; ++p)
    for (int i = 0; i < centres; ++i) {
      const double t = p / per - ShearFieldTable::kMarginSigmas - i, g = std::exp(-0.5 * t * t);
      value(p, i) = g, slope(p, i) = -t * g / per;
    }
}

/// Cubic Hermite basis at u in [0, 1): values at the cell's two ends (H0, H1) and slopes
/// (K0, K1, for values of h times the derivative).
struct Hermite {
  double h0, h1, k0, k1;
  explicit Hermite(double u) {
    const double v = 1 - u;
    h0 = (1 + 2 * u) * v * v, h1 = u * u * (3 - 2 * u), k0 = u * v * v, k1 = -u * u * v;
  }
};
}  // namespace

ShearFieldTable::ShearFieldTable(const ShearFields& fields) {
  if (fields.empty()) return;
  const double sigma = fields.sigma_mm;
  // Nodes along one axis of a plane (the bumps' centres and 6 sigmas either side).
  auto along = [&](int axis, int per) {
    return static_cast<long long>(fields.count(axis) - 1 + 2 * kMarginSigmas) * per + 1;
  };
  auto nodes = [&](int per) {
    return along(1, per) * along(2, per) + along(0, per) * along(2, per) +
           along(0, per) * along(1, per);
  };
  while (per_sigma_ > 4 && nodes(per_sigma_) > 8'000'000)
    --per_sigma_;
  h_mm_ = sigma / per_sigma_;
  const auto& sums = detail::bump_sum_bounds();
  const double a0 = sums[0], a1 = sums[1], a4 = sums[4];
  const double r = 1.0 / per_sigma_, r3 = r * r * r, r4 = r3 * r;
  // The bicubic Hermite remainder, f - Hb Hc f = (f - Hb f) + Hb (f - Hc f): a cubic
  // Hermite interpolant's error is at most h^4 / 384 |f''''| and its derivative's
  // (sqrt 3 / 216) h^3 |f''''| (Birkhoff and Priver 1967; taken here as h^3 / 24), and for
  // any e, |Hb e| <= max |e| + (8 / 27) h max |e'| and |(Hb e)'| <= (3 / h) max |e| + 2 max
  // |e'| (the basis' largest values and slopes). A field's derivatives are at most its
  // largest weight times the bump sums' bounds, a_m a_n / sigma^(m + n).
  const double c1 = 1.0 / 24;
  for (int a = 0; a < 3; ++a) {
    const double w = fields.largest_weight(a);
    error_.value_mm[static_cast<size_t>(a)] = w * r4 / 384 * (2 * a4 * a0 + 8.0 / 27 * r * a1 * a4);
    const double along_b = c1 * r3 * a4 * a0 + 3 * r3 / 384 * a0 * a4 + 2 * r4 / 384 * a1 * a4;
    const double along_c = r4 / 384 * a4 * a1 + c1 * r3 * a0 * a4 + 8.0 / 27 * c1 * r4 * a1 * a4;
    error_.gradient[static_cast<size_t>(a)] = w / sigma * (along_b + along_c);
  }
  for (int a = 0; a < 3; ++a) {
    Plane& plane = planes_[static_cast<size_t>(a)];
    std::tie(plane.b, plane.c) = detail::other_axes(a);
    const int cb = fields.count(plane.b), cc = fields.count(plane.c);
    plane.nb = static_cast<int>(along(plane.b, per_sigma_));
    plane.nc = static_cast<int>(along(plane.c, per_sigma_));
    plane.origin_b = fields.origin_mm(plane.b) - kMarginSigmas * sigma;
    plane.origin_c = fields.origin_mm(plane.c) - kMarginSigmas * sigma;
    // f = Gb W Gc^T and its derivatives, W the heights (centre (i, j) at W(i, j)).
    const auto weights = fields.heights(a);
    Eigen::MatrixXd gb, db, gc, dc;
    node_rows(cb, plane.nb, per_sigma_, gb, db);
    node_rows(cc, plane.nc, per_sigma_, gc, dc);
    const Eigen::MatrixXd gw = gb * weights, dw = db * weights;
    const Eigen::MatrixXd f = gw * gc.transpose(), fb = dw * gc.transpose(),
                          fc = gw * dc.transpose(), fbc = dw * dc.transpose();
    plane.node.resize(4 * static_cast<size_t>(plane.nb) * static_cast<size_t>(plane.nc));
    for (int q = 0; q < plane.nc; ++q)
      for (int p = 0; p < plane.nb; ++p) {
        double* n =
            plane.node.data() +
            4 * (static_cast<size_t>(p) + static_cast<size_t>(plane.nb) * static_cast<size_t>(q));
        n[0] = f(p, q), n[1] = fb(p, q), n[2] = fc(p, q), n[3] = fbc(p, q);
      }
  }
}

double ShearFieldTable::field(int a, const Eigen::Vector3d& q) const {
  const Plane& plane = planes_[static_cast<size_t>(a)];
  if (plane.node.empty()) return 0;
  const double s = (q(plane.b) - plane.origin_b) / h_mm_, t = (q(plane.c) - plane.origin_c) / h_mm_;
  if (!(s >= 0 && t >= 0 && s < plane.nb - 1 && t < plane.nc - 1)) return 0;
  const int p = static_cast<int>(s), r = static_cast<int>(t);
  const Hermite hb(s - p), hc(t - r);
  const double vb[2] = {hb.h0, hb.h1}, kb[2] = {hb.k0, hb.k1};
  const double vc[2] = {hc.h0, hc.h1}, kc[2] = {hc.k0, hc.k1};
  double f = 0;
  for (int dq = 0; dq < 2; ++dq)
    for (int dp = 0; dp < 2; ++dp) {
      const double* n =
          plane.node.data() + 4 * (static_cast<size_t>(p + dp) +
                                   static_cast<size_t>(plane.nb) * static_cast<size_t>(r + dq));
      f += vb[dp] * vc[dq] * n[0] + kb[dp] * vc[dq] * n[1] + vb[dp] * kc[dq] * n[2] +
           kb[dp] * kc[dq] * n[3];
    }
  return f;
}

Eigen::Vector3d ShearFieldTable::apply(const Eigen::Vector3d& q) const {
  Eigen::Vector3d u = q;
  if (empty()) return u;
  for (int a = 0; a < 3; ++a)
    u(a) += field(a, u);
  return u;
}

Eigen::Vector3d ShearFieldTable::inverse(const Eigen::Vector3d& q) const {
  Eigen::Vector3d u = q;  // undo the fields in reverse order
  if (empty()) return u;
  for (int a = 2; a >= 0; --a)
    u(a) -= field(a, u);
  return u;
}

}  // namespace organfit::fitting
