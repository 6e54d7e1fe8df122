#pragma once
// The body re-made in the global map's shape: the reference mapped, then filled at the
// model's own lattice density with the same count, so its volume is kept.
#include <vector>

#include "organfit/fitting/global_map.h"
#include "organfit/geometry/image_geometry.h"
#include "organfit/geometry/signed_distance.h"
#include "organfit/particles/state.h"

namespace organfit::fitting {

/// The model's reference body (the mask it was filled from) mapped by `map` and re-filled
/// with exactly `count` particles: the deepest sites of an fcc lattice of spacing
/// `a_nn_mm` inside the mapped body. Same count, same density: the same volume. The
/// reference, not the particles' own ball surface, is mapped: re-sampling the balls
/// would add a second discretisation error to the first.
particles::Positions refill_mapped_body(const geometry::LabelVolume& reference, int count,
                                        double a_nn_mm, const GlobalMap& map);

/// The same in two steps, for re-fills of one map with several counts: the lattice's sites
/// over the mapped body ranked by their signed depth in the reference (made once: the
/// map's inverse at every site), then any count of them taken. `depth` is the reference's
/// unsmoothed signed distance (SignedDistance(reference, false)); at a voxel centre it
/// ranks as the distance across the boundary does.
class MappedBodySites {
 public:
  MappedBodySites(const geometry::LabelVolume& reference, const geometry::SignedDistance& depth,
                  double a_nn_mm, const GlobalMap& map);
  /// The deepest `count` sites as one body (refill_mapped_body).
  particles::Positions fill(int count) const;

 private:
  double a_nn_mm_ = 1;
  particles::Positions sites_;
  std::vector<int> ranked_;  ///< sites on the reference's grid, deepest first
};

}  // namespace organfit::fitting
