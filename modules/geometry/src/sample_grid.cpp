#include "organfit/geometry/sample_grid.h"

namespace organfit::geometry {

std::vector<std::pair<int, double>> SampleGrid::nearest_each(const Eigen::Matrix3Xd& queries,
                                                             double box_mm) const {
  const Eigen::Index m = queries.cols();
  std::vector<std::pair<int, double>> out(static_cast<size_t>(m),
                                          {-1, std::numeric_limits<double>::infinity()});
  if (m == 0 || points_.cols() == 0) return out;
  // The queries by box (a box's queries consecutive, in ascending index).
  const Eigen::Vector3d lo = queries.rowwise().minCoeff();
  const Eigen::Vector3d extent = queries.rowwise().maxCoeff() - lo;
  // At most about 1,000 boxes a side (a far query makes them larger, not more).
  const double box = std::max({box_mm, extent.maxCoeff() / 1000, 1e-6});
  Eigen::Array3i boxes;
  for (int a = 0; a < 3; ++a)
    boxes[a] = static_cast<int>(extent[a] / box) + 1;
  std::vector<std::pair<long long, int>> keyed(static_cast<size_t>(m));
  for (Eigen::Index i = 0; i < m; ++i) {
    long long key = 0;
    for (int a = 2; a >= 0; --a)
      key =
          key * boxes[a] + std::min(boxes[a] - 1, static_cast<int>((queries(a, i) - lo[a]) / box));
    keyed[static_cast<size_t>(i)] = {key, static_cast<int>(i)};
  }
  std::sort(keyed.begin(), keyed.end());
  std::vector<size_t> group = {0};  // [group[g], group[g + 1]) of keyed: one box
  for (size_t i = 1; i < keyed.size(); ++i)
    if (keyed[i].first != keyed[i - 1].first) group.push_back(i);
  group.push_back(keyed.size());
  const double half_diagonal = 0.5 * std::sqrt(3.0) * box;
  const auto groups = static_cast<long>(group.size()) - 1;
#pragma omp parallel
  {
    std::vector<int> candidates;  // places k in points_
#pragma omp for schedule(dynamic, 4)
    for (long g = 0; g < groups; ++g) {
      long long key = keyed[group[static_cast<size_t>(g)]].first;
      Eigen::Vector3d centre;
      for (int a = 0; a < 3; ++a) {
        centre[a] = lo[a] + (static_cast<double>(key % boxes[a]) + 0.5) * box;
        key /= boxes[a];
      }
      const double d0 = std::sqrt(nearest(centre).second);
      const double reach = (d0 + 2 * half_diagonal) * (1 + 1e-12) + 1e-12;
      candidates.clear();
      places_within(centre, reach, candidates);
      for (size_t e = group[static_cast<size_t>(g)]; e < group[static_cast<size_t>(g) + 1]; ++e) {
        const Eigen::Vector3d q = queries.col(keyed[e].second);
        std::pair<int, double> best{-1, std::numeric_limits<double>::infinity()};
        for (int k : candidates) {
          const double d2 = (points_.col(k) - q).squaredNorm();
          const int j = order_[static_cast<size_t>(k)];
          if (d2 < best.second || (d2 == best.second && j < best.first)) best = {j, d2};
        }
        out[static_cast<size_t>(keyed[e].second)] = best;
      }
    }
  }
  return out;
}

}  // namespace organfit::geometry
