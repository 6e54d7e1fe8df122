#include "organfit/fitting/global_map.h"

#include <Eigen/LU>
#include <algorithm>
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
