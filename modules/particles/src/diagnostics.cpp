#include "organfit/particles/diagnostics.h"

#include <Eigen/Eigenvalues>
#include <numeric>
#include <vector>

#include "organfit/particles/neighbour_list.h"

namespace organfit::particles {
namespace {
int find_root(std::vector<int>& parent, int i) {
  while (parent[i] != i) i = parent[i] = parent[parent[i]];
  return i;
}
}  // namespace

int connected_components(const Positions& x, double link_mm) {
  const int n = static_cast<int>(x.cols());
  if (n == 0) return 0;
  // The neighbour list with a tiny skin lists every pair closer than link_mm (+ skin).
  NeighbourList list(link_mm, 1e-6 * link_mm);
  list.update(x);
  std::vector<int> parent(n);
  std::iota(parent.begin(), parent.end(), 0);
  const auto& order = list.order();
  const double link2 = link_mm * link_mm;
  for (int s = 0; s < n; ++s) {
    for (int k = list.first()[s]; k < list.first()[s + 1]; ++k) {
      const int i = order[s], j = order[list.neighbours()[k]];
      if ((x.col(i) - x.col(j)).squaredNorm() >= link2) continue;
      parent[find_root(parent, i)] = find_root(parent, j);
    }
  }
  int components = 0;
  for (int i = 0; i < n; ++i) components += find_root(parent, i) == i;
  return components;
}

Eigen::Vector3d principal_extents(const Positions& x) {
  if (x.cols() < 2) return Eigen::Vector3d::Zero();
  const Eigen::Vector3d mean = x.rowwise().mean();
  const Eigen::Matrix3Xd c = x.colwise() - mean;
  const Eigen::Matrix3d cov = c * c.transpose() / static_cast<double>(x.cols());
  Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> es(cov);
  const Eigen::Vector3d ev = es.eigenvalues().cwiseMax(0).cwiseSqrt();  // ascending
  return {ev[2], ev[1], ev[0]};
}

}  // namespace organfit::particles
