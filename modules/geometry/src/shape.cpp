#include "organfit/geometry/shape.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <limits>
#include <stdexcept>
#include <vector>

namespace organfit::geometry {

namespace {
/// The egg's cross-section scale at x (centred, mm): 1 at the +x end and at the middle,
/// 0.7 at the -x tip; it grows with x.
double egg_taper(double x, double semi_x) {
  const double t = std::clamp(x / semi_x, -1.0, 1.0);
  return t < 0 ? 1.0 + 0.3 * t : 1.0;
}

/// The lung's notch: a sphere cut from the ellipsoid's -x side (centred coordinates, mm).
struct Notch {
  Eigen::Vector3d centre;
  double radius;
};
Notch lung_notch(const Eigen::Vector3d& semi) {
  return {Eigen::Vector3d(-semi.x() * 1.05, 0, -0.2 * semi.z()), 0.55 * semi.x()};
}
}  // namespace

bool Shape::inside(const Eigen::Vector3d& p) const {
  if (mask) return distance->beyond_level(p) < 0;
  const Eigen::Vector3d semi = 0.5 * size_mm;
  const Eigen::Vector3d q = p - centre_mm;
  if (kind == Kind::box) return (q.cwiseAbs().array() <= semi.array()).all();
  if (kind == Kind::egg) {
    const double taper = egg_taper(q.x(), semi.x());
    const Eigen::Vector3d s(semi.x(), semi.y() * taper, semi.z() * taper);
    return q.cwiseQuotient(s).squaredNorm() <= 1.0;
  }
  const bool in_ellipsoid = q.cwiseQuotient(semi).squaredNorm() <= 1.0;
  if (kind == Kind::lung) {
    const Notch notch = lung_notch(semi);
    return in_ellipsoid && (q - notch.centre).norm() > notch.radius;
  }
  return in_ellipsoid;
}

namespace {
/// Where a ball of radius r about q (centred coordinates) lies against the ellipsoid of
/// semi-axes `semi`: |q / semi| changes by at most r / min(semi) over the ball.
BallSide ellipsoid_ball(const Eigen::Vector3d& q, double r, const Eigen::Vector3d& semi) {
  const double f = q.cwiseQuotient(semi).norm(), reach = r / semi.minCoeff();
  constexpr double kRounding = 1e-9;
  if (f + reach < 1 - kRounding) return BallSide::inside;
  if (f - reach > 1 + kRounding) return BallSide::outside;
  return BallSide::unknown;
}
}  // namespace

BallSide Shape::inside_ball(const Eigen::Vector3d& p, double radius_mm) const {
  if (!(radius_mm >= 0) || !p.allFinite()) return BallSide::unknown;
  if (mask) {
    constexpr double kRounding = 1e-9;  // mm
    const double v = distance->beyond_level(p);
    const double reach =
        (distance->gradient_bound(p, radius_mm) + distance->volume_level_slope()) * radius_mm +
        kRounding;
    return v < -reach ? BallSide::inside : v > reach ? BallSide::outside : BallSide::unknown;
  }
  const Eigen::Vector3d semi = 0.5 * size_mm;
  const Eigen::Vector3d q = p - centre_mm;
  const double r = radius_mm;
  constexpr double kRounding = 1e-9;
  switch (kind) {
    case Kind::box: {
      const Eigen::Vector3d margin = semi - q.cwiseAbs();  // > r on every axis: inside
      if ((margin.array() > r + kRounding * semi.array()).all()) return BallSide::inside;
      if ((margin.array() < -r - kRounding * semi.array()).any()) return BallSide::outside;
      return BallSide::unknown;
    }
    case Kind::egg: {
      // The taper grows with x: over the ball's x-range it lies in [taper(x - r),
      // taper(x + r)], and the egg there holds the ellipsoid of the least taper and lies
      // within that of the largest.
      const double least = egg_taper(q.x() - r, semi.x()), most = egg_taper(q.x() + r, semi.x());
      if (ellipsoid_ball(q, r, Eigen::Vector3d(semi.x(), semi.y() * least, semi.z() * least)) ==
          BallSide::inside)
        return BallSide::inside;
      if (ellipsoid_ball(q, r, Eigen::Vector3d(semi.x(), semi.y() * most, semi.z() * most)) ==
          BallSide::outside)
        return BallSide::outside;
      return BallSide::unknown;
    }
    case Kind::lung: {
      const BallSide in_ellipsoid = ellipsoid_ball(q, r, semi);
      if (in_ellipsoid == BallSide::outside) return BallSide::outside;
      const Notch notch = lung_notch(semi);
      const double to_notch = (q - notch.centre).norm(), notch_r = notch.radius;
      if (to_notch + r < notch_r * (1 - kRounding)) return BallSide::outside;  // in the notch
      if (in_ellipsoid == BallSide::inside && to_notch - r > notch_r * (1 + kRounding))
        return BallSide::inside;
      return BallSide::unknown;
    }
    case Kind::ellipsoid:
      return ellipsoid_ball(q, r, semi);
    case Kind::mask:
      break;
  }
  return BallSide::unknown;
}

const char* Shape::kind_name() const {
  switch (kind) {
    case Kind::box:
      return "box";
    case Kind::egg:
      return "egg";
    case Kind::lung:
      return "lung";
    case Kind::mask:
      return "mask";
    case Kind::ellipsoid:
      break;
  }
  return "ellipsoid";
}

Shape make_shape(const std::string& kind, const Eigen::Vector3d& size_mm,
                 const Eigen::Vector3d& centre_mm) {
  Shape shape;
  if (kind == "ellipsoid")
    shape.kind = Shape::Kind::ellipsoid;
  else if (kind == "box")
    shape.kind = Shape::Kind::box;
  else if (kind == "egg")
    shape.kind = Shape::Kind::egg;
  else if (kind == "lung")
    shape.kind = Shape::Kind::lung;
  else
    throw std::invalid_argument("unknown shape '" + kind + "' (ellipsoid, box, egg, lung)");
  if (!(size_mm.array() > 0).all()) throw std::invalid_argument("shape size must be > 0 mm");
  shape.size_mm = size_mm, shape.centre_mm = centre_mm;
  return shape;
}

Aabb Shape::extent() const {
  if (!mask) return bounds();
  // In the distance grid's frame: beyond a face the organ reaches (the scan cut it), a
  // point p is inside where (the value at its nearest grid point q, on that face) + |p - q|
  // < level, so it lies within level - (the face's least value) of the face along its axis
  // (beyond an edge, within each of its faces' reach along that face's axis). The grid's
  // index box grown so, in patient coordinates, joins the box.
  const ImageGeometry& g = distance->geometry();
  Eigen::Vector3d lo = Eigen::Vector3d::Zero(), hi(g.size[0] - 1, g.size[1] - 1, g.size[2] - 1);
  bool reached = false;
  const double highest = distance->highest_volume_level();
  for (int d = 0; d < 3; ++d) {
    const int a = (d + 1) % 3, b = (d + 2) % 3;
    for (int side = 0; side < 2; ++side) {
      double least = std::numeric_limits<double>::infinity();
      int idx[3];
      idx[d] = side ? g.size[d] - 1 : 0;
      for (int v = 0; v < g.size[b]; ++v)
        for (int u = 0; u < g.size[a]; ++u) {
          idx[a] = u, idx[b] = v;
          least = std::min(least, distance->at_voxel(idx[0], idx[1], idx[2]));
        }
      if (!(highest - least > 0)) continue;
      reached = true;
      const double reach_voxels = (highest - least) / g.spacing_mm[d];
      (side ? hi : lo)[d] += side ? reach_voxels : -reach_voxels;
    }
  }
  if (!reached) return box;
  const Aabb grown =
      image_of_box({lo, hi}, [&g](const Eigen::Vector3d& i) { return g.index_to_physical(i); });
  return {grown.min_mm.cwiseMin(box.min_mm), grown.max_mm.cwiseMax(box.max_mm)};
}

Shape make_mask_shape(std::shared_ptr<const LabelVolume> mask,
                      std::optional<SignedDistance::VolumeLevels> levels) {
  const auto& g = mask->geometry;
  Shape s;
  s.kind = Shape::Kind::mask;
  Eigen::Vector3d lo = Eigen::Vector3d::Constant(1e300), hi = -lo, sum = Eigen::Vector3d::Zero();
  long long n = 0;
  const Eigen::Vector3d half = 0.5 * (g.direction * g.spacing_mm).cwiseAbs();
  for (int k = 0; k < g.size[2]; ++k)
    for (int j = 0; j < g.size[1]; ++j)
      for (int i = 0; i < g.size[0]; ++i) {
        if (mask->at(i, j, k) != 1) continue;
        const Eigen::Vector3d p = g.index_to_physical(Eigen::Vector3d(i, j, k));
        lo = lo.cwiseMin(p - half), hi = hi.cwiseMax(p + half), sum += p, ++n;
      }
  if (n == 0) throw std::invalid_argument("the organ mask is empty");
  s.centre_mm = sum / static_cast<double>(n);
  s.size_mm = hi - lo;
  // The level lies between a voxel of label 1 and its neighbour across the boundary.
  s.box = {lo - half, hi + half};
  // The distance on the organ's voxels and one about them (cropped_organ): a CT's whole grid
  // would take 8 bytes a voxel.
  auto distance = std::make_shared<SignedDistance>(cropped_organ(*mask), false);
  if (levels) distance->adopt_volume_levels(*levels);
  // Its levels and gradient bound found here, not by the first of many threads asking.
  (void)distance->volume_level();
  (void)distance->gradient_bound();
  s.distance = std::move(distance);
  s.mask = std::move(mask);
  return s;
}

LabelVolume shape_on_grid(const Shape& shape, const ImageGeometry& grid, const IndexRange& range) {
  LabelVolume out(grid);
  label_by_blocks(
      out, range, [&](const Eigen::Vector3d& c, double r) { return shape.inside_ball(c, r); },
      [&](const Eigen::Vector3d& p) { return shape.inside(p); });
  return out;
}

Eigen::Vector3d ray_origin_mm(const Shape& shape) {
  if (!shape.mask || shape.inside(shape.centre_mm)) return shape.centre_mm;
  const LabelVolume& mask = *shape.mask;
  const ImageGeometry& g = mask.geometry;
  // The label-1 voxels' index box, grown by one voxel: the distance transform then sees the
  // outside all round, even where the organ touches its grid's faces.
  const IndexRange organ = mask.range(1);
  if (organ.empty()) throw std::invalid_argument("the organ mask is empty");
  const std::array<int, 3>&lo = organ.lo, &hi = organ.hi;
  ImageGeometry box = g;
  for (int a = 0; a < 3; ++a)
    box.size[a] = hi[a] - lo[a] + 3;
  box.origin_mm = g.index_to_physical(Eigen::Vector3d(lo[0] - 1, lo[1] - 1, lo[2] - 1));
  std::vector<std::uint8_t> outside(static_cast<size_t>(box.voxel_count()), 1);
  for (int k = 1; k + 1 < box.size[2]; ++k)
    for (int j = 1; j + 1 < box.size[1]; ++j)
      for (int i = 1; i + 1 < box.size[0]; ++i)
        outside[static_cast<size_t>(box.linear_index(i, j, k))] =
            mask.at(lo[0] - 1 + i, lo[1] - 1 + j, lo[2] - 1 + k) != 1;
  const GridBuffer<double> depth2 = squared_distance_transform(outside, box);
  long long deepest = 0;
  for (long long v = 1; v < box.voxel_count(); ++v)
    if (depth2[static_cast<size_t>(v)] > depth2[static_cast<size_t>(deepest)]) deepest = v;
  const long long nx = box.size[0], ny = box.size[1];
  return box.index_to_physical(Eigen::Vector3d(static_cast<double>(deepest % nx),
                                               static_cast<double>(deepest / nx % ny),
                                               static_cast<double>(deepest / (nx * ny))));
}

double shape_volume_mm3(const Shape& shape, double voxel_mm) {
  const Aabb b = shape.bounds();
  long long n = 0;
  for (double z = b.min_mm.z() + 0.5 * voxel_mm; z < b.max_mm.z(); z += voxel_mm)
    for (double y = b.min_mm.y() + 0.5 * voxel_mm; y < b.max_mm.y(); y += voxel_mm)
      for (double x = b.min_mm.x() + 0.5 * voxel_mm; x < b.max_mm.x(); x += voxel_mm)
        n += shape.inside({x, y, z});
  return static_cast<double>(n) * voxel_mm * voxel_mm * voxel_mm;
}

}  // namespace organfit::geometry
