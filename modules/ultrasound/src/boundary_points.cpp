#include "organfit/ultrasound/boundary_points.h"

#include <fmt/format.h>

#include <Eigen/Geometry>
#include <Eigen/LU>
#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>
#include <string>
#include <vector>

#include "organfit/geometry/image_geometry.h"
#include "organfit/ultrasound/sequence_metafile.h"

namespace organfit::ultrasound {
namespace {

/// Separable Gaussian of `v` on a box of `size` voxels with per-axis sigma (voxels).
void gaussian_smooth(std::vector<float>& v, const std::array<int, 3>& size,
                     const Eigen::Vector3d& sigma) {
  std::vector<float> line;
  for (int d = 0; d < 3; ++d) {
    if (!(sigma[d] > 0.3)) continue;
    const int radius = static_cast<int>(std::ceil(3 * sigma[d]));
    std::vector<double> kernel(2 * radius + 1);
    double sum = 0;
    for (int t = -radius; t <= radius; ++t)
      sum += kernel[t + radius] = std::exp(-0.5 * t * t / (sigma[d] * sigma[d]));
    for (auto& k : kernel)
      k /= sum;
    const long long stride = d == 0 ? 1 : d == 1 ? size[0] : 1LL * size[0] * size[1];
    const int n = size[d];
    const long long lines = 1LL * size[0] * size[1] * size[2] / n;
#pragma omp parallel for schedule(static) private(line)
    for (long long l = 0; l < lines; ++l) {
      // The first voxel of line l: index over the other two axes.
      long long base;
      if (d == 0)
        base = l * size[0];
      else if (d == 1)
        base = (l / size[0]) * size[0] * size[1] + (l % size[0]);
      else
        base = l;
      line.resize(static_cast<size_t>(n));
      for (int t = 0; t < n; ++t)
        line[t] = v[static_cast<size_t>(base + t * stride)];
      for (int t = 0; t < n; ++t) {
        double acc = 0;
        for (int q = -radius; q <= radius; ++q)
          acc += kernel[q + radius] * line[std::clamp(t + q, 0, n - 1)];
        v[static_cast<size_t>(base + t * stride)] = static_cast<float>(acc);
      }
    }
  }
}

}  // namespace

void check_field_of_view(const std::vector<double>& extent_mm) {
  constexpr double kSmallestMm = 1, kLargestMm = 1000;
  std::string sides;
  bool plausible = true;
  for (const double e : extent_mm) {
    sides += fmt::format("{}{:g}", sides.empty() ? "" : " x ", e);
    plausible = plausible && e >= kSmallestMm && e <= kLargestMm;
  }
  if (!plausible)
    throw std::invalid_argument(fmt::format(
        "its field of view is {} mm: not an ultrasound image's ({:g} mm to {:g} m a side; its "
        "pixel size or calibration in another unit, or damaged?)",
        sides, kSmallestMm, kLargestMm / 1000));
}

BoundaryResult boundary_points(const geometry::ImageGeometry& g,
                               const std::vector<float>& intensity,
                               const std::vector<std::uint8_t>* in_view, const BoundaryOptions& o) {
  if (intensity.size() != static_cast<size_t>(g.voxel_count()) ||
      (in_view && in_view->size() != intensity.size()))
    throw std::invalid_argument("boundary_points: image sizes do not match the geometry");
  if (!(o.r_max_mm > o.r_min_mm) || o.rays < 16)
    throw std::invalid_argument("boundary_points: bad search range");
  check_field_of_view(
      {g.size[0] * g.spacing_mm[0], g.size[1] * g.spacing_mm[1], g.size[2] * g.spacing_mm[2]});
  const Eigen::Vector3d c_idx = g.physical_to_index(o.centre_mm);
  for (int d = 0; d < 3; ++d)
    if (!(c_idx[d] > -0.5 && c_idx[d] < g.size[d] - 0.5))
      throw std::invalid_argument(
          "boundary_points: the organ's centre is outside the ultrasound volume");

  // 1. The region of interest, smoothed.
  std::array<int, 3> lo{}, size{};
  for (int d = 0; d < 3; ++d) {
    const int half =
        static_cast<int>(std::ceil((o.r_max_mm + 3 * o.smoothing_mm) / g.spacing_mm[d])) + 1;
    const int c = static_cast<int>(std::lround(c_idx[d]));
    lo[d] = std::max(0, c - half);
    size[d] = std::min(g.size[d] - 1, c + half) - lo[d] + 1;
  }
  std::vector<float> roi(static_cast<size_t>(size[0]) * size[1] * size[2]);
  std::vector<std::uint8_t> roi_view(roi.size(), 1);
  for (int k = 0; k < size[2]; ++k)
    for (int j = 0; j < size[1]; ++j)
      for (int i = 0; i < size[0]; ++i) {
        const auto from = static_cast<size_t>(g.linear_index(lo[0] + i, lo[1] + j, lo[2] + k));
        const size_t to = i + static_cast<size_t>(size[0]) * (j + static_cast<size_t>(size[1]) * k);
        roi[to] = intensity[from];
        if (in_view) roi_view[to] = (*in_view)[from];
      }
  gaussian_smooth(roi, size, o.smoothing_mm * g.spacing_mm.cwiseInverse());
  auto sample = [&](const Eigen::Vector3d& p, bool& ok) -> double {  // trilinear, ROI voxels
    const Eigen::Vector3d idx = g.physical_to_index(p) - Eigen::Vector3d(lo[0], lo[1], lo[2]);
    const Eigen::Vector3d base = idx.array().floor();
    ok = (base.array() >= 0).all() &&
         (base.array() < Eigen::Array3d(size[0] - 1, size[1] - 1, size[2] - 1)).all();
    if (!ok) return 0;
    double value = 0;
    geometry::for_each_trilinear_corner(idx - base, [&](int di, int dj, int dk, double weight) {
      const int i = static_cast<int>(base.x()) + di, j = static_cast<int>(base.y()) + dj,
                k = static_cast<int>(base.z()) + dk;
      const size_t at = i + static_cast<size_t>(size[0]) * (j + static_cast<size_t>(size[1]) * k);
      if (!roi_view[at]) ok = false;
      value += weight * roi[at];
    });
    return value;
  };

  // 2-3. Rays on a Fibonacci sphere; neighbours are the 8 nearest directions.
  const int n = o.rays;
  std::vector<Ray> rays(n);
  const double golden = 3.14159265358979323846 * (3 - std::sqrt(5.0));
  for (int r = 0; r < n; ++r) {
    const double z = 1 - 2 * (r + 0.5) / n, rho = std::sqrt(1 - z * z);
    rays[r] = {o.centre_mm,
               Eigen::Vector3d(rho * std::cos(golden * r), rho * std::sin(golden * r), z)};
  }
  std::vector<std::vector<int>> neighbours(n);
#pragma omp parallel for schedule(dynamic, 64)
  for (int r = 0; r < n; ++r) {
    std::vector<std::pair<double, int>> near;
    for (int q = 0; q < n; ++q)
      if (q != r) near.push_back({-rays[r].direction.dot(rays[q].direction), q});
    std::partial_sort(near.begin(), near.begin() + 8, near.end());
    for (int q = 0; q < 8; ++q)
      neighbours[r].push_back(near[q].second);
  }
  return search_rays(
      rays, neighbours, [&](int, const Eigen::Vector3d& p, bool& ok) { return sample(p, ok); },
      0.25 * g.spacing_mm.minCoeff(), o);
}

BoundaryResult sweep_boundary_points(const TrackedSweep& sweep, const BoundaryOptions& o,
                                     int rays_per_frame) {
  if (rays_per_frame < 16)
    throw std::invalid_argument("sweep_boundary_points: at least 16 rays per frame");
  struct Plane {
    const TrackedFrame* frame;
    std::vector<float> smooth;
    Eigen::Vector3d origin, eu, ev;
    Eigen::Matrix2d gram_inverse;
  };
  std::vector<Plane> planes;
  std::vector<Ray> rays;
  std::vector<int> plane_of;
  std::vector<std::vector<int>> neighbours;
  for (const auto& f : sweep.frames) {
    if (f.pixels.size() != static_cast<size_t>(f.width) * f.height || f.width < 4 || f.height < 4)
      continue;
    check_field_of_view({f.pixel_to_ct_mm.block<3, 1>(0, 0).norm() * f.width,
                         f.pixel_to_ct_mm.block<3, 1>(0, 1).norm() * f.height});
    Plane pl;
    pl.frame = &f;
    pl.origin = f.pixel_to_ct_mm.block<3, 1>(0, 3);
    pl.eu = f.pixel_to_ct_mm.block<3, 1>(0, 0);
    pl.ev = f.pixel_to_ct_mm.block<3, 1>(0, 1);
    const Eigen::Vector3d normal = pl.eu.cross(pl.ev).normalized();
    const double distance = (o.centre_mm - pl.origin).dot(normal);
    if (!(std::abs(distance) < o.r_max_mm)) continue;
    Eigen::Matrix2d gram;
    gram << pl.eu.dot(pl.eu), pl.eu.dot(pl.ev), pl.ev.dot(pl.eu), pl.ev.dot(pl.ev);
    pl.gram_inverse = gram.inverse();
    pl.smooth = f.pixels;
    gaussian_smooth(
        pl.smooth, {f.width, f.height, 1},
        Eigen::Vector3d(o.smoothing_mm / pl.eu.norm(), o.smoothing_mm / pl.ev.norm(), 0));
    const Eigen::Vector3d centre = o.centre_mm - distance * normal;
    const int first = static_cast<int>(rays.size());
    const Eigen::Vector3d u = pl.eu.normalized(), v = normal.cross(u);
    for (int a = 0; a < rays_per_frame; ++a) {
      const double t = 2 * 3.14159265358979323846 * a / rays_per_frame;
      rays.push_back({centre, std::cos(t) * u + std::sin(t) * v});
      plane_of.push_back(static_cast<int>(planes.size()));
      std::vector<int> near;
      for (int k = 1; k <= 4; ++k) {
        near.push_back(first + (a + k) % rays_per_frame);
        near.push_back(first + (a - k + rays_per_frame) % rays_per_frame);
      }
      neighbours.push_back(std::move(near));
    }
    planes.push_back(std::move(pl));
  }
  if (rays.empty()) return {};
  double step = 1e9;
  for (const auto& pl : planes)
    step = std::min(step, 0.5 * std::min(pl.eu.norm(), pl.ev.norm()));
  return search_rays(
      rays, neighbours,
      [&](int ray, const Eigen::Vector3d& p, bool& ok) -> double {
        const Plane& pl = planes[static_cast<size_t>(plane_of[static_cast<size_t>(ray)])];
        const Eigen::Vector3d rel = p - pl.origin;
        const Eigen::Vector2d ab =
            pl.gram_inverse * Eigen::Vector2d(rel.dot(pl.eu), rel.dot(pl.ev));
        const int w = pl.frame->width, h = pl.frame->height;
        const double fa = std::floor(ab.x()), fb = std::floor(ab.y());
        ok = fa >= 0 && fb >= 0 && fa < w - 1 && fb < h - 1;
        if (!ok) return 0;
        const double ta = ab.x() - fa, tb = ab.y() - fb;
        const size_t at = static_cast<size_t>(fb) * w + static_cast<size_t>(fa);
        return (1 - ta) * (1 - tb) * pl.smooth[at] + ta * (1 - tb) * pl.smooth[at + 1] +
               (1 - ta) * tb * pl.smooth[at + w] + ta * tb * pl.smooth[at + w + 1];
      },
      step, o);
}

BoundaryResult search_rays(const std::vector<Ray>& rays,
                           const std::vector<std::vector<int>>& neighbours,
                           const RaySampler& sample, double step, const BoundaryOptions& o) {
  const int n = static_cast<int>(rays.size());
  std::vector<double> radius(n, -1), rise(n, 0);
#pragma omp parallel for schedule(dynamic, 16)
  for (int r = 0; r < n; ++r) {
    const Ray& ray = rays[r];
    double from = o.r_min_mm, to = o.r_max_mm;
    if (o.prior_inside) {  // where the prior's surface crosses the ray (its last inside sample)
      double surface = -1;
      for (double s = 0; s <= o.r_max_mm + o.band_mm; s += 0.5)
        if (o.prior_inside(ray.origin + s * ray.direction)) surface = s;
      if (surface < 0) continue;
      from = std::max(o.r_min_mm, surface - o.band_mm), to = surface + o.band_mm;
    }
    std::vector<double> profile;
    bool ok = true;
    for (double s = from; s <= to; s += step) {
      const double v = sample(r, ray.origin + s * ray.direction, ok);
      if (!ok) break;
      profile.push_back(v);
    }
    const int m = static_cast<int>(profile.size());
    const int h = std::max(1, static_cast<int>(std::lround(0.5 * o.smoothing_mm / step)));
    if (m < 2 * h + 3) continue;
    // The first strong rise outward: a dark gland into its capsule's bright line or fat.
    std::vector<double> d(m, 0);
    double best = 0;
    for (int s = h; s + h < m; ++s)
      best = std::max(best, d[s] = profile[s + h] - profile[s - h]);
    if (!(best > 0)) continue;
    for (int s = h + 1; s + h + 1 < m; ++s)
      if (d[s] >= 0.5 * best && d[s] >= d[s - 1] && d[s] >= d[s + 1]) {
        radius[r] = from + s * step;
        rise[r] = d[s];
        break;
      }
  }
  BoundaryResult out;
  out.rays = n;
  double max_rise = 0;
  std::vector<double> rises;
  for (int r = 0; r < n; ++r)
    if (radius[r] > 0)
      ++out.rays_in_view, max_rise = std::max(max_rise, rise[r]), rises.push_back(rise[r]);
  // A ray whose best edge is weak against the boundary's typical one has found speckle
  // or a fading interface, not the capsule: no boundary on it.
  if (!rises.empty()) {
    std::nth_element(rises.begin(), rises.begin() + static_cast<long>(rises.size() / 2),
                     rises.end());
    const double weak = o.weak_edge_fraction * rises[rises.size() / 2];
    for (int r = 0; r < n; ++r)
      if (radius[r] > 0 && rise[r] < weak) radius[r] = -1, ++out.weak;
  }

  // 4. Neighbour consistency of the radius.
  std::vector<double> residual(n, std::numeric_limits<double>::quiet_NaN());
  for (int r = 0; r < n; ++r) {
    if (radius[r] <= 0) continue;
    std::vector<double> rs;
    for (int q : neighbours[r])
      if (radius[q] > 0) rs.push_back(radius[q]);
    if (rs.size() < 3) continue;
    std::nth_element(rs.begin(), rs.begin() + static_cast<long>(rs.size() / 2), rs.end());
    residual[r] = radius[r] - rs[rs.size() / 2];
  }
  std::vector<double> abs_res;
  for (double v : residual)
    if (std::isfinite(v)) abs_res.push_back(std::abs(v));
  double cutoff = std::numeric_limits<double>::infinity();
  if (!abs_res.empty()) {
    std::nth_element(abs_res.begin(), abs_res.begin() + static_cast<long>(abs_res.size() / 2),
                     abs_res.end());
    cutoff = std::max(0.5, o.mad_threshold * 1.4826 * abs_res[abs_res.size() / 2]);
  }
  std::vector<BoundaryPoint> accepted;
  std::vector<Eigen::Vector3d> accepted_dirs;
  for (int r = 0; r < n; ++r) {
    if (radius[r] <= 0) continue;
    if (!std::isfinite(residual[r]) || std::abs(residual[r]) > cutoff) {
      ++out.rejected;
      continue;
    }
    const Eigen::Vector3d p = rays[r].origin + radius[r] * rays[r].direction;
    accepted.push_back({p, std::clamp(rise[r] / max_rise, 0.1, 1.0)});
    accepted_dirs.push_back((p - o.centre_mm).normalized());
  }

  // 5. Spread over the boundary.
  if (o.target_count <= 0 || static_cast<int>(accepted.size()) <= o.target_count) {
    out.points = std::move(accepted);
    return out;
  }
  size_t first = 0;
  for (size_t a = 1; a < accepted.size(); ++a)
    if (accepted[a].confidence > accepted[first].confidence) first = a;
  std::vector<double> gap(accepted.size(), std::numeric_limits<double>::infinity());
  size_t last = first;
  out.points.push_back(accepted[first]);
  while (static_cast<int>(out.points.size()) < o.target_count) {
    size_t best = 0;
    double best_gap = -1;
    for (size_t a = 0; a < accepted.size(); ++a) {
      // Spread over directions, not positions: a far-off point must not be preferred.
      gap[a] = std::min(gap[a], (accepted_dirs[a] - accepted_dirs[last]).norm());
      if (gap[a] > best_gap) best_gap = gap[a], best = a;
    }
    if (best_gap <= 0) break;
    out.points.push_back(accepted[best]);
    last = best;
  }
  return out;
}

}  // namespace organfit::ultrasound
