#include "organfit/fitting/refill.h"

#include <Eigen/LU>
#include <algorithm>
#include <cmath>
#include <numeric>

#include "organfit/geometry/mask_ops.h"
#include "organfit/geometry/sample_grid.h"
#include "organfit/particles/diagnostics.h"
#include "organfit/particles/lattice_fill.h"

namespace organfit::fitting {

MappedBodySites::MappedBodySites(const geometry::LabelVolume& reference,
                                 const geometry::SignedDistance& depth, double a_nn_mm,
                                 const GlobalMap& map)
    : a_nn_mm_(a_nn_mm) {
  const geometry::ImageGeometry& g = reference.geometry;
  // Signed depth in the reference body at the nearest voxel centre: the distance to the
  // nearest centre across the boundary (less half a voxel), negated so that deeper ranks
  // higher. Ranking sites by it selects a level set of the mapped body, which can sit a
  // little outside it when the count asks so.
  const double off_grid = -std::numeric_limits<double>::infinity();
  auto depth_at = [&](const Eigen::Vector3d& q) {
    const Eigen::Vector3d idx = g.physical_to_index(q);
    const int i = static_cast<int>(std::lround(idx.x())),
              j = static_cast<int>(std::lround(idx.y())),
              k = static_cast<int>(std::lround(idx.z()));
    if (i < 0 || j < 0 || k < 0 || i >= g.size[0] || j >= g.size[1] || k >= g.size[2])
      return off_grid;
    return -depth.at_voxel(i, j, k);
  };
  // Candidate sites: the lattice over the mapped box, centred on the mapped centroid.
  const geometry::Aabb box = g.bounds_mm();
  Eigen::Vector3d centroid = Eigen::Vector3d::Zero();
  long long inside = 0;
  for (int k = 0; k < g.size[2]; ++k)
    for (int j = 0; j < g.size[1]; ++j)
      for (int i = 0; i < g.size[0]; ++i)
        if (reference.at(i, j, k))
          centroid += g.index_to_physical(Eigen::Vector3d(i, j, k)), ++inside;
  centroid /= static_cast<double>(std::max<long long>(1, inside));
  geometry::Aabb mapped =
      geometry::image_of_box(box, [&map](const Eigen::Vector3d& p) { return map.apply(p); });
  mapped.min_mm.array() -= a_nn_mm;  // room for a level set just outside the body
  mapped.max_mm.array() += a_nn_mm;
  sites_ = particles::fcc_lattice_points(mapped, map.apply(centroid), a_nn_mm,
                                         [](const Eigen::Vector3d&) { return true; });
  const particles::Positions& sites = sites_;
  std::vector<double> d(sites.cols());
  const Eigen::Matrix3d a_inverse = map.affine.a.inverse();
  const long n = static_cast<long>(sites.cols());
#pragma omp parallel for schedule(static)
  for (long s = 0; s < n; ++s)
    d[s] = depth_at(map.inverse(sites.col(s), a_inverse));
  // Sites by signed depth, deepest first (ties by index: deterministic); sites off the
  // reference's grid are never taken.
  std::vector<int>& idx = ranked_;
  for (Eigen::Index s = 0; s < sites.cols(); ++s)
    if (d[s] > off_grid) idx.push_back(static_cast<int>(s));
  std::stable_sort(idx.begin(), idx.end(), [&](int l, int r) { return d[l] > d[r]; });
}

particles::Positions MappedBodySites::fill(int count, int pieces) const {
  if (count <= 0) return particles::Positions(3, 0);
  const particles::Positions& sites = sites_;
  const std::vector<int>& idx = ranked_;
  const double a_nn_mm = a_nn_mm_;
  const int keep = std::min<int>(count, static_cast<int>(idx.size()));
  // The body: the largest `pieces` groups of the deepest `keep` sites (joined within 1.2
  // a_nn), topped up with the next deepest sites that touch them.
  const double link2 = (1.2 * a_nn_mm) * (1.2 * a_nn_mm);
  particles::Positions chosen(3, keep);
  for (int s = 0; s < keep; ++s)
    chosen.col(s) = sites.col(idx[s]);
  const std::vector<int> body =
      particles::largest_components(chosen, 1.2 * a_nn_mm, std::max(1, pieces));
  std::vector<char> taken(sites.cols(), 0);
  std::vector<int> result;
  for (int b : body)
    result.push_back(idx[b]), taken[idx[b]] = 1;
  for (size_t q = keep; q < idx.size() && static_cast<int>(result.size()) < keep; ++q) {
    const int s = idx[q];
    for (int r : result)
      if ((sites.col(s) - sites.col(r)).squaredNorm() < link2) {
        result.push_back(s), taken[s] = 1;
        break;
      }
  }
  std::sort(result.begin(), result.end());
  particles::Positions out(3, static_cast<Eigen::Index>(result.size()));
  for (size_t s = 0; s < result.size(); ++s)
    out.col(static_cast<Eigen::Index>(s)) = sites.col(result[s]);
  return out;
}

}  // namespace organfit::fitting
