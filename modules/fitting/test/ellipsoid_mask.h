#pragma once
// The global fit's test organ: the ellipsoid x^2/25^2 + y^2/20^2 + z^2/17^2 <= 1 (mm) as a
// mask of 0.75 mm voxels, and its surface sampled as the fit stage samples its reference.
#include <Eigen/Core>

#include "organfit/fitting/surface_samples.h"
#include "organfit/geometry/mask_ops.h"

namespace organfit::fitting::test {

inline const Eigen::Vector3d kEllipsoidSemiAxesMm(25, 20, 17);

inline geometry::LabelVolume ellipsoid_mask() {
  const Eigen::Vector3d& semi = kEllipsoidSemiAxesMm;
  const geometry::ImageGeometry g = geometry::grid_covering({-semi, semi}, 0.75, 3.0);
  geometry::LabelVolume mask(g);
  for (int k = 0; k < g.size[2]; ++k)
    for (int j = 0; j < g.size[1]; ++j)
      for (int i = 0; i < g.size[0]; ++i)
        mask.at(i, j, k) =
            g.index_to_physical(Eigen::Vector3d(i, j, k)).cwiseQuotient(semi).squaredNorm() <= 1;
  return mask;
}

inline SurfaceSamples ellipsoid_mask_surface() {
  return reference_surface(ellipsoid_mask(), 2);
}

}  // namespace organfit::fitting::test
