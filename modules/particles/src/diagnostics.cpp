#include "organfit/particles/diagnostics.h"

#include <Eigen/Eigenvalues>
#include <Eigen/LU>
#include <Eigen/SVD>
#include <algorithm>
#include <numeric>
#include <vector>

#include "organfit/particles/neighbour_list.h"

namespace organfit::particles {
namespace {
int find_root(std::vector<int>& parent, int i) {
  while (parent[i] != i)
    i = parent[i] = parent[parent[i]];
  return i;
}
}  // namespace

namespace {
/// Union-find root of every particle, joining pairs closer than link_mm.
std::vector<int> component_roots(const Positions& x, double link_mm) {
  const int n = static_cast<int>(x.cols());
  std::vector<int> parent(n);
  std::iota(parent.begin(), parent.end(), 0);
  if (n == 0) return parent;
  // The neighbour list with a tiny skin lists every pair closer than link_mm (+ skin).
  NeighbourList list(link_mm, 1e-6 * link_mm);
  list.update(x);
  const auto& order = list.order();
  const double link2 = link_mm * link_mm;
  for (int s = 0; s < n; ++s) {
    for (int k = list.first()[s]; k < list.first()[s + 1]; ++k) {
      const int i = order[s], j = order[list.neighbours()[k]];
      if ((x.col(i) - x.col(j)).squaredNorm() >= link2) continue;
      parent[find_root(parent, i)] = find_root(parent, j);
    }
  }
  for (int i = 0; i < n; ++i)
    parent[i] = find_root(parent, i);
  return parent;
}
}  // namespace

int connected_components(const Positions& x, double link_mm) {
  const std::vector<int> root = component_roots(x, link_mm);
  int components = 0;
  for (int i = 0; i < static_cast<int>(root.size()); ++i)
    components += root[i] == i;
  return components;
}

std::vector<int> largest_component(const Positions& x, double link_mm) {
  return largest_components(x, link_mm, 1);
}

std::vector<int> largest_components(const Positions& x, double link_mm, int count) {
  const std::vector<int> root = component_roots(x, link_mm);
  std::vector<int> size(root.size(), 0);
  for (int r : root)
    ++size[r];
  std::vector<int> roots;  // one per component, ascending: ties keep this order
  for (int i = 0; i < static_cast<int>(root.size()); ++i)
    if (root[i] == i) roots.push_back(i);
  const int keep = std::clamp(count, 0, static_cast<int>(roots.size()));
  std::stable_sort(roots.begin(), roots.end(), [&](int l, int r) { return size[l] > size[r]; });
  std::vector<char> kept(root.size(), 0);
  for (int c = 0; c < keep; ++c)
    kept[roots[c]] = 1;
  std::vector<int> members;
  for (int i = 0; i < static_cast<int>(root.size()); ++i)
    if (kept[root[i]]) members.push_back(i);
  return members;
}

Positions rigid_align(const Positions& moving, const Positions& fixed) {
  if (moving.cols() != fixed.cols() || moving.cols() == 0) return moving;
  const Eigen::Vector3d cm = moving.rowwise().mean(), cf = fixed.rowwise().mean();
  const Eigen::Matrix3d h = (moving.colwise() - cm) * (fixed.colwise() - cf).transpose();
  Eigen::JacobiSVD<Eigen::Matrix3d> svd(h, Eigen::ComputeFullU | Eigen::ComputeFullV);
  Eigen::Matrix3d v = svd.matrixV();
  if ((v * svd.matrixU().transpose()).determinant() < 0) v.col(2) *= -1;
  const Eigen::Matrix3d r = v * svd.matrixU().transpose();
  return (r * (moving.colwise() - cm)).colwise() + cf;
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
