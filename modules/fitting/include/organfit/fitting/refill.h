#pragma once
// The body re-made in the global map's shape: the reference mapped, then filled at the
// model's own lattice density with the same count, so its volume is kept.
#include <vector>

#include "organfit/fitting/global_map.h"
#include "organfit/geometry/image_geometry.h"
#include "organfit/geometry/signed_distance.h"
#include "organfit/particles/state.h"

namespace organfit::fitting {

/// The model's reference body (the mask it was filled from) mapped by `map`, and the
/// sites of an fcc lattice of spacing `a_nn_mm` over it ranked by their signed depth in
/// the reference (made once per map: the map's inverse at every site). fill(count) takes
/// the deepest `count` as the body: same count, same density, the same volume, for
/// re-fills of one map with several counts. The reference, not the particles' own ball
/// surface, is mapped: re-sampling the balls would add a second discretisation error to
/// the first. `depth` is the reference's unsmoothed signed distance
/// (SignedDistance(reference, false)); at a voxel centre it ranks as the distance across
/// the boundary does.
class MappedBodySites {
 public:
  MappedBodySites(const geometry::LabelVolume& reference, const geometry::SignedDistance& depth,
                  double a_nn_mm, const GlobalMap& map);
  /// The deepest `count` sites (fewer when the lattice has fewer) as a body of `pieces`
  /// pieces (the planning body's: an organ in two parts stays in two): the largest
  /// `pieces` connected groups of them, topped up with the next deepest that touch one.
  /// Smaller groups are sites of thin parts cut off at the count's depth, dropped.
  particles::Positions fill(int count, int pieces = 1) const;

 private:
  double a_nn_mm_ = 1;
  particles::Positions sites_;
  std::vector<int> ranked_;  ///< sites on the reference's grid, deepest first
};

}  // namespace organfit::fitting
