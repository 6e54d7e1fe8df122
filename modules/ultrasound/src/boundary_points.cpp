#include "organfit/ultrasound/boundary_points.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>

namespace organfit::ultrasound {
namespace {

/// Separable Gaussian of `v` on a box of `size` voxels with per-axis sigma (voxels).
void gaussian_smooth(std::vector<float>& v, const std::array<int, 3>& size, const Eigen::Vector3d& sigma) {
  std::vector<float> line;
  for (int d = 0; d < 3; ++d) {
    if (!(sigma[d] > 0.3)) continue;
    const int radius = static_cast<int>(std::ceil(3 * sigma[d]));
    std::vector<double> kernel(2 * radius + 1);
    double sum = 0;
    for (int t = -radius; t <= radius; ++t) sum += kernel[t + radius] = std::exp(-0.5 * t * t / (sigma[d] * sigma[d]));
    for (auto& k : kernel) k /= sum;
    const long long stride = d == 0 ? 1 : d == 1 ? size[0] : 1LL * size[0] * size[1];
    const int n = size[d];
    const long long lines = 1LL * size[0] * size[1] * size[2] / n;
#pragma omp parallel for schedule(static) private(line)
    for (long long l = 0; l < lines; ++l) {
      // The first voxel of line l: index over the other two axes.
      long long base;
      if (d == 0) base = l * size[0];
      else if (d == 1) base = (l / size[0]) * size[0] * size[1] + (l % size[0]);
      else base = l;
      line.resize(static_cast<size_t>(n));
      for (int t = 0; t < n; ++t) line[t] = v[static_cast<size_t>(base + t * stride)];
      for (int t = 0; t < n; ++t) {
        double acc = 0;
        for (int q = -radius; q <= radius; ++q) acc += kernel[q + radius] * line[std::clamp(t + q, 0, n - 1)];
        v[static_cast<size_t>(base + t * stride)] = static_cast<float>(acc);
      }
    }
  }
}

}  // namespace

BoundaryResult boundary_points(const geometry::ImageGeometry& g, const std::vector<float>& intensity,
                               const std::vector<std::uint8_t>* in_view, const BoundaryOptions& o) {
  if (intensity.size() != static_cast<size_t>(g.voxel_count()) || (in_view && in_view->size() != intensity.size()))
    throw std::invalid_argument("boundary_points: image sizes do not match the geometry");
  if (!(o.r_max_mm > o.r_min_mm) || o.rays < 16) throw std::invalid_argument("boundary_points: bad search range");
  const Eigen::Vector3d c_idx = g.physical_to_index(o.centre_mm);
  for (int d = 0; d < 3; ++d)
    if (!(c_idx[d] > -0.5 && c_idx[d] < g.size[d] - 0.5))
      throw std::invalid_argument("boundary_points: the organ's centre is outside the ultrasound volume");

  // 1. The region of interest, smoothed.
  std::array<int, 3> lo{}, size{};
  for (int d = 0; d < 3; ++d) {
    const int half = static_cast<int>(std::ceil((o.r_max_mm + 3 * o.smoothing_mm) / g.spacing_mm[d])) + 1;
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
    ok = (base.array() >= 0).all() && (base.array() < Eigen::Array3d(size[0] - 1, size[1] - 1, size[2] - 1)).all();
    if (!ok) return 0;
    const Eigen::Vector3d t = idx - base;
    double value = 0;
    for (int c = 0; c < 8; ++c) {
      const int i = static_cast<int>(base.x()) + (c & 1), j = static_cast<int>(base.y()) + ((c >> 1) & 1),
                k = static_cast<int>(base.z()) + ((c >> 2) & 1);
      const size_t at = i + static_cast<size_t>(size[0]) * (j + static_cast<size_t>(size[1]) * k);
      if (!roi_view[at]) ok = false;
      value += ((c & 1) ? t.x() : 1 - t.x()) * (((c >> 1) & 1) ? t.y() : 1 - t.y()) * (((c >> 2) & 1) ? t.z() : 1 - t.z()) * roi[at];
    }
    return value;
  };

  // 2-3. Rays on a Fibonacci sphere.
  const int n = o.rays;
  std::vector<Eigen::Vector3d> dirs(n);
  const double golden = 3.14159265358979323846 * (3 - std::sqrt(5.0));
  for (int r = 0; r < n; ++r) {
    const double z = 1 - 2 * (r + 0.5) / n, rho = std::sqrt(1 - z * z);
    dirs[r] = Eigen::Vector3d(rho * std::cos(golden * r), rho * std::sin(golden * r), z);
  }
  const double step = 0.25 * g.spacing_mm.minCoeff();
  std::vector<double> radius(n, -1), rise(n, 0);
#pragma omp parallel for schedule(dynamic, 16)
  for (int r = 0; r < n; ++r) {
    double from = o.r_min_mm, to = o.r_max_mm;
    if (o.prior_inside) {  // where the prior's surface crosses the ray (its last inside sample)
      double surface = -1;
      for (double s = 0; s <= o.r_max_mm + o.band_mm; s += 0.5)
        if (o.prior_inside(o.centre_mm + s * dirs[r])) surface = s;
      if (surface < 0) continue;
      from = std::max(o.r_min_mm, surface - o.band_mm), to = surface + o.band_mm;
    }
    std::vector<double> profile;
    bool ok = true;
    for (double s = from; s <= to; s += step) {
      const double v = sample(o.centre_mm + s * dirs[r], ok);
      if (!ok) break;
      profile.push_back(v);
    }
    const int m = static_cast<int>(profile.size());
    const int h = std::max(1, static_cast<int>(std::lround(0.5 * o.smoothing_mm / step)));
    if (m < 2 * h + 3) continue;
    // The first strong rise outward: a dark gland into its capsule's bright line or fat.
    std::vector<double> d(m, 0);
    double best = 0;
    for (int s = h; s + h < m; ++s) best = std::max(best, d[s] = profile[s + h] - profile[s - h]);
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
    if (radius[r] > 0) ++out.rays_in_view, max_rise = std::max(max_rise, rise[r]), rises.push_back(rise[r]);
  // A ray whose best edge is weak against the boundary's typical one has found speckle
  // or a fading interface, not the capsule: no boundary on it.
  if (!rises.empty()) {
    std::nth_element(rises.begin(), rises.begin() + static_cast<long>(rises.size() / 2), rises.end());
    const double weak = o.weak_edge_fraction * rises[rises.size() / 2];
    for (int r = 0; r < n; ++r)
      if (radius[r] > 0 && rise[r] < weak) radius[r] = -1, ++out.weak;
  }

  // 4. Neighbour consistency of the radius.
  std::vector<double> residual(n, std::numeric_limits<double>::quiet_NaN());
  for (int r = 0; r < n; ++r) {
    if (radius[r] <= 0) continue;
    std::vector<std::pair<double, int>> near;
    for (int q = 0; q < n; ++q)
      if (q != r && radius[q] > 0) near.push_back({-dirs[r].dot(dirs[q]), q});
    if (near.size() < 3) continue;
    const size_t k = std::min<size_t>(8, near.size());
    std::partial_sort(near.begin(), near.begin() + static_cast<long>(k), near.end());
    std::vector<double> rs;
    for (size_t q = 0; q < k; ++q) rs.push_back(radius[near[q].second]);
    std::nth_element(rs.begin(), rs.begin() + static_cast<long>(rs.size() / 2), rs.end());
    residual[r] = radius[r] - rs[rs.size() / 2];
  }
  std::vector<double> abs_res;
  for (double v : residual)
    if (std::isfinite(v)) abs_res.push_back(std::abs(v));
  double cutoff = std::numeric_limits<double>::infinity();
  if (!abs_res.empty()) {
    std::nth_element(abs_res.begin(), abs_res.begin() + static_cast<long>(abs_res.size() / 2), abs_res.end());
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
    accepted.push_back({o.centre_mm + radius[r] * dirs[r], std::clamp(rise[r] / max_rise, 0.1, 1.0)});
    accepted_dirs.push_back(dirs[r]);
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
