#pragma once
// A body's voxels on a grid, labelled coarse to fine: a block of voxels that a test places
// wholly on one side of the body's surface is set at once, any other is halved, down to
// single voxels, each tested. The labels are those of testing every voxel; the cost is set
// by the surface's area rather than the body's volume.
#include <Eigen/Core>
#include <functional>

#include "organfit/geometry/image_geometry.h"

namespace organfit::geometry {

/// Which side of a surface a whole ball lies on: every point inside, every point outside,
/// or either (not known).
enum class BallSide { inside, outside, unknown };

/// Sets `out`'s voxels in `range` to 1 inside, 0 outside, in blocks of up to 16 voxels a
/// side, coarse to fine.
///  - ball(centre_mm, radius_mm): the side every point within the radius of the centre lies
///    on, or unknown; never wrong. Asked of each block of more than one voxel, with the ball
///    through its corner voxels' centres.
///  - inside(centre_mm): whether a voxel whose centre is there is inside (asked of single
///    voxels).
/// Both are called from several threads; each writes nothing.
void label_by_blocks(LabelVolume& out, const IndexRange& range,
                     const std::function<BallSide(const Eigen::Vector3d&, double)>& ball,
                     const std::function<bool(const Eigen::Vector3d&)>& inside);

}  // namespace organfit::geometry
