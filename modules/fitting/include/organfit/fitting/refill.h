#pragma once
// The body re-made in the global map's shape: the reference mapped, then filled at the
// model's own lattice density with the same count, so its volume is kept.
#include "organfit/fitting/global_map.h"
#include "organfit/geometry/image_geometry.h"
#include "organfit/particles/state.h"

namespace organfit::fitting {

/// The model's reference body (the mask it was filled from) mapped by `map` and re-filled
/// with exactly `count` particles: the deepest sites of an fcc lattice of spacing
/// `a_nn_mm` inside the mapped body. Same count, same density: the same volume. The
/// reference, not the particles' own ball surface, is mapped: re-sampling the balls
/// would add a second discretisation error to the first.
particles::Positions refill_mapped_body(const geometry::LabelVolume& reference, int count,
                                        double a_nn_mm, const GlobalMap& map);

}  // namespace organfit::fitting
