#pragma once
// Where an organ meets the edge of the grid it lies on. A mask with voxels on the last plane
// of its grid along some axis may go on beyond it: the grid (a CT's field of view) does not
// show whether it ends there, and what is drawn on it is cut there.
#include <array>

#include "organfit/geometry/image_geometry.h"

namespace organfit::geometry {

/// Label-1 voxels of `mask` on each face of its grid, in the order -i, +i, -j, +j, -k, +k.
std::array<long long, 6> voxels_on_faces(const LabelVolume& mask);

/// The patient side face `face` (0 to 5, as voxels_on_faces orders them) of grid `g` looks
/// towards, by the largest component of its outward axis in patient coordinates (LPS: +x
/// left, +y posterior, +z superior): "right", "left", "anterior", "posterior", "inferior" or
/// "superior".
const char* side_of_face(const ImageGeometry& g, int face);

}  // namespace organfit::geometry
