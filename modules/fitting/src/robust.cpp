#include "organfit/fitting/robust.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <unordered_map>

#include "cell_key.h"

namespace organfit::fitting {

namespace {

double median_of(std::vector<double>& v) {
  const size_t mid = v.size() / 2;
  std::nth_element(v.begin(), v.begin() + static_cast<long>(mid), v.end());
  return v[mid];
}

}  // namespace

double outlier_cutoff(std::vector<double> values, double mads, double min_mad) {
  if (values.empty()) return std::numeric_limits<double>::infinity();
  const double median = median_of(values);
  for (double& v : values)
    v = std::abs(v - median);
  return median + mads * 1.4826 * std::max(median_of(values), min_mad);
}

std::vector<std::vector<int>> k_nearest(const std::vector<Eigen::Vector3d>& points, int k) {
  const int n = static_cast<int>(points.size());
  std::vector<std::vector<int>> out(static_cast<size_t>(n));
  k = std::min(k, n - 1);
  if (k <= 0) return out;
  Eigen::Vector3d lo = points[0], hi = points[0];
  for (const auto& p : points)
    lo = lo.cwiseMin(p), hi = hi.cwiseMax(p);
  // Cells of about two points each over the points' box, its flat sides counted as one
  // cell thick (a sheet of points gets square cells, not slivers); at most 2^19 cells
  // along an axis (cell_key's range). The neighbours found do not depend on the cells.
  const Eigen::Vector3d extent = hi - lo;
  double cell = std::max(extent.maxCoeff(), 1e-9);
  for (int it = 0; it < 12; ++it)
    cell = std::cbrt(2.0 * extent.cwiseMax(cell).prod() / n);
  cell = std::max({cell, extent.maxCoeff() / (1 << 19), 1e-9});
  auto index = [&](const Eigen::Vector3d& p) {
    return Eigen::Array3i(((p - lo) / cell).array().floor().cast<int>());
  };
  std::unordered_map<long long, std::vector<int>> cells;
  for (int i = 0; i < n; ++i) {
    const Eigen::Array3i c = index(points[static_cast<size_t>(i)]);
    cells[cell_key(c.matrix())].push_back(i);
  }
  const Eigen::Array3i last = index(hi);
  const int max_ring = last.maxCoeff() + 1;
  std::vector<std::pair<double, int>> found;
  for (int i = 0; i < n; ++i) {
    const Eigen::Vector3d& p = points[static_cast<size_t>(i)];
    const Eigen::Array3i c = index(p);
    found.clear();
    // Rings of cells outward; a point in ring r is at least (r - 1) cells away, so once
    // k are found within that distance no farther ring can hold a nearer one.
    for (int r = 0; r <= max_ring; ++r) {
      for (int a = c.x() - r; a <= c.x() + r; ++a)
        for (int b = c.y() - r; b <= c.y() + r; ++b)
          for (int d = c.z() - r; d <= c.z() + r; ++d) {
            if (std::max({std::abs(a - c.x()), std::abs(b - c.y()), std::abs(d - c.z())}) != r ||
                a < 0 || b < 0 || d < 0 || a > last.x() || b > last.y() || d > last.z())
              continue;
            const auto it = cells.find(cell_key(Eigen::Vector3i(a, b, d)));
            if (it == cells.end()) continue;
            for (int j : it->second)
              if (j != i) found.push_back({(points[static_cast<size_t>(j)] - p).squaredNorm(), j});
          }
      if (static_cast<int>(found.size()) >= k) {
        std::nth_element(found.begin(), found.begin() + (k - 1), found.end());
        const double reach = r * cell;
        if (found[static_cast<size_t>(k - 1)].first <= reach * reach) break;
      }
    }
    std::sort(found.begin(), found.end());
    for (int q = 0; q < k && q < static_cast<int>(found.size()); ++q)
      out[static_cast<size_t>(i)].push_back(found[static_cast<size_t>(q)].second);
  }
  return out;
}

std::vector<char> normalised_median_test(const std::vector<double>& values,
                                         const std::vector<std::vector<int>>& neighbours,
                                         const std::vector<char>& use, double threshold,
                                         double epsilon, int min_support) {
  std::vector<char> outlier(values.size(), 0);
  std::vector<double> v, dev;
  for (size_t i = 0; i < values.size(); ++i) {
    if (!use[i]) continue;
    v.clear();
    for (int j : neighbours[i])
      if (use[static_cast<size_t>(j)]) v.push_back(values[static_cast<size_t>(j)]);
    if (v.size() < 3) continue;
    dev = v;
    const double m = median_of(v);
    for (double& d : dev)
      d = std::abs(d - m);
    const double tolerance = threshold * (median_of(dev) + epsilon);
    if (std::abs(values[i] - m) <= tolerance) continue;
    int support = 0;  // neighbours that agree with this value
    for (double vj : v)
      support += std::abs(vj - values[i]) <= tolerance;
    outlier[i] = support < min_support;
  }
  return outlier;
}

}  // namespace organfit::fitting
