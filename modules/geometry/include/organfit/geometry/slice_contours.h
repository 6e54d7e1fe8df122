#pragma once
// Per-slice contours of a label mask, for RT Structure Sets.
//
// Marching squares on each k slice, through the voxel centres, at level 0.5: the
// contour passes half-way between every inside and outside voxel centre, so filling
// the polygons by the even-odd rule (voxel centres inside) gives the mask back. Saddle
// cells join the two inside corners (the organ 8-connected in a slice, as topology_of's
// pieces are 26-connected in 3D). Loops are closed; vertices on straight runs
// are dropped (exact), then a loop with more points than allowed is thinned
// (Douglas-Peucker) with a tolerance doubled from 0.05 voxel until it fits.
#include <Eigen/Core>
#include <vector>

#include "organfit/geometry/image_geometry.h"

namespace organfit::geometry {

struct SliceContour {
  int k = 0;                               ///< slice index
  std::vector<Eigen::Vector3d> points_mm;  ///< closed (last joins first), patient mm
  double thinning_tolerance_mm = 0;        ///< 0 when only collinear points were dropped
};

/// Contours of `label` in `mask`, slice by slice. `max_points` bounds one contour (a
/// DICOM Contour Data element holds at most 65,534 bytes: about 2,000 points).
std::vector<SliceContour> slice_contours(const LabelVolume& mask, std::uint8_t label,
                                         int max_points = 2000);

/// A slice on which two sets of contours of one organ (same grid) count differently.
struct ContourCountChange {
  int k = 0;                  ///< slice index
  int before = 0, after = 0;  ///< contours on it
};

/// The slices that both `before` and `after` cut on which their numbers of contours
/// differ, by slice index. A slice only one of them cuts is left out: the organ moved
/// onto it or off it, which is not a change of its topology.
std::vector<ContourCountChange> contour_count_changes(const std::vector<SliceContour>& before,
                                                      const std::vector<SliceContour>& after);

}  // namespace organfit::geometry
