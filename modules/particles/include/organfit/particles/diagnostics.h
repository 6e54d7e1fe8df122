#pragma once
// Measurements of a particle configuration used by tests, fits and benchmarks.
#include <Eigen/Core>
#include <vector>

#include "organfit/particles/state.h"

namespace organfit::particles {

/// Number of connected components when particles closer than `link_mm` are joined
/// (grid + union-find, O(N)). A body torn apart has more than one.
int connected_components(const Positions& x, double link_mm);

/// Indices of the particles in the largest connected component (link as above).
std::vector<int> largest_component(const Positions& x, double link_mm);

/// Indices, ascending, of the particles in the `count` largest connected components (link
/// as above; components of one size in a fixed order): the
/// pieces of a body of `count` pieces, without the stray ones.
std::vector<int> largest_components(const Positions& x, double link_mm, int count);

/// Standard deviations of the positions along their principal axes, largest first (mm).
Eigen::Vector3d principal_extents(const Positions& x);

/// Ratio of the largest to the smallest principal extent (1 for a sphere).
inline double aspect_ratio(const Positions& x) {
  const Eigen::Vector3d e = principal_extents(x);
  return e[2] > 0 ? e[0] / e[2] : 0.0;
}

/// `moving` rigidly moved (rotation + translation, Kabsch) to best match `fixed`,
/// particle by particle. Removes the drift and turn of a whole body before a comparison.
Positions rigid_align(const Positions& moving, const Positions& fixed);

/// True when every coordinate is finite.
inline bool all_finite(const Eigen::Matrix3Xd& m) {
  return m.allFinite();
}

}  // namespace organfit::particles
