#include "organfit/particles/lattice_fill.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <utility>
#include <vector>

#include "organfit/geometry/morton.h"

namespace organfit::particles {

double fcc_equilibrium_spacing(const LennardJones& law) {
  // Virial per particle, sum_j r_j LJ(r_j) over lattice vectors inside the cutoff, for the
  // lattice scaled to nearest-neighbour distance a. Equilibrium (zero pressure at zero
  // temperature) is its root: positive (repulsive) below, negative above.
  const double rc = law.cutoff();
  auto virial = [&](double a) {
    const double cube = a * std::sqrt(2.0);
    const int reach = static_cast<int>(std::ceil(rc / cube)) + 1;
    double w = 0;
    for (int i = -reach; i <= reach; ++i)
      for (int j = -reach; j <= reach; ++j)
        for (int k = -reach; k <= reach; ++k)
          for (const auto& b : kFccBasis) {
            const double r = cube * Eigen::Vector3d(i + b[0], j + b[1], k + b[2]).norm();
            if (r > 0 && r < rc) w += r * law.force(r);
          }
    return w;
  };
  // Bisection on [floor, r0]: the nearest shell repels below r0 at any cutoff.
  double lo = law.floor_distance() * 1.0001, hi = law.r0();
  if (virial(hi) >= 0) return hi;  // nothing beyond the first shell attracts
  for (int it = 0; it < 200 && hi - lo > 1e-13 * law.r0(); ++it) {
    const double mid = 0.5 * (lo + hi);
    (virial(mid) > 0 ? lo : hi) = mid;
  }
  return 0.5 * (lo + hi);
}

Positions fcc_lattice_points(const geometry::Aabb& box, const Eigen::Vector3d& centre_mm,
                             double a_nn_mm,
                             const std::function<bool(const Eigen::Vector3d&)>& inside) {
  const double cube = a_nn_mm * std::sqrt(2.0);
  const double tol = 1e-9 * a_nn_mm;  // points on the box faces are inside
  Eigen::Vector3i lo, hi;
  for (int d = 0; d < 3; ++d) {
    lo[d] = static_cast<int>(std::floor((box.min_mm[d] - centre_mm[d]) / cube)) - 1;
    hi[d] = static_cast<int>(std::ceil((box.max_mm[d] - centre_mm[d]) / cube)) + 1;
  }
  // Z-order (Morton) of the cubic cells, the basis site last: particles near in space are
  // near in memory at every scale, so a neighbour list's slots, a skeleton cluster's
  // members and a patch of skin read few runs of memory (LAMMPS sorts atoms by bins for
  // the same reason). Reproducible: the key is a function of the site alone.
  std::vector<std::pair<std::uint64_t, Eigen::Vector3d>> pts;
  for (int k = lo.z(); k <= hi.z(); ++k)
    for (int j = lo.y(); j <= hi.y(); ++j)
      for (int i = lo.x(); i <= hi.x(); ++i) {
        const std::uint64_t cell = geometry::morton_code(static_cast<std::uint64_t>(i - lo.x()),
                                                         static_cast<std::uint64_t>(j - lo.y()),
                                                         static_cast<std::uint64_t>(k - lo.z()));
        for (int b = 0; b < 4; ++b) {
          const Eigen::Vector3d p =
              centre_mm +
              cube * Eigen::Vector3d(i + kFccBasis[b][0], j + kFccBasis[b][1], k + kFccBasis[b][2]);
          if ((p.array() < box.min_mm.array() - tol).any() ||
              (p.array() > box.max_mm.array() + tol).any())
            continue;
          if (inside(p)) pts.push_back({cell << 2 | static_cast<std::uint64_t>(b), p});
        }
      }
  std::sort(pts.begin(), pts.end(), [](const auto& a, const auto& b) { return a.first < b.first; });
  Positions out(3, static_cast<Eigen::Index>(pts.size()));
  for (size_t i = 0; i < pts.size(); ++i)
    out.col(static_cast<Eigen::Index>(i)) = pts[i].second;
  return out;
}

Positions fill_box(const Eigen::Vector3d& size_mm, const Eigen::Vector3d& centre_mm,
                   double a_nn_mm) {
  geometry::Aabb box{centre_mm - 0.5 * size_mm, centre_mm + 0.5 * size_mm};
  return fcc_lattice_points(box, centre_mm, a_nn_mm, [](const Eigen::Vector3d&) { return true; });
}

Positions fill_ellipsoid(const Eigen::Vector3d& size_mm, const Eigen::Vector3d& centre_mm,
                         double a_nn_mm) {
  const Eigen::Vector3d semi = 0.5 * size_mm;
  geometry::Aabb box{centre_mm - semi, centre_mm + semi};
  return fcc_lattice_points(box, centre_mm, a_nn_mm, [&](const Eigen::Vector3d& p) {
    return (p - centre_mm).cwiseQuotient(semi).squaredNorm() <= 1.0;
  });
}

Positions fill_mask(const geometry::LabelVolume& mask, std::uint8_t label, double a_nn_mm) {
  // Bounding box of the labelled voxels (their centres, widened by half a voxel).
  const auto& g = mask.geometry;
  Eigen::Vector3d lo = Eigen::Vector3d::Constant(std::numeric_limits<double>::infinity());
  Eigen::Vector3d hi = -lo;
  Eigen::Vector3d sum = Eigen::Vector3d::Zero();
  long long count = 0;
  const Eigen::Vector3d half = 0.5 * (g.direction * g.spacing_mm).cwiseAbs();
  for (int k = 0; k < g.size[2]; ++k)
    for (int j = 0; j < g.size[1]; ++j)
      for (int i = 0; i < g.size[0]; ++i) {
        if (mask.at(i, j, k) != label) continue;
        const Eigen::Vector3d p = g.index_to_physical(Eigen::Vector3d(i, j, k));
        lo = lo.cwiseMin(p - half);
        hi = hi.cwiseMax(p + half);
        sum += p;
        ++count;
      }
  if (count == 0) return Positions(3, 0);
  const Eigen::Vector3d centre = sum / static_cast<double>(count);
  return fcc_lattice_points({lo, hi}, centre, a_nn_mm,
                            [&](const Eigen::Vector3d& p) { return mask.at_physical(p) == label; });
}

}  // namespace organfit::particles
