#pragma once
// An organ segmented from CT pixels by seeded region growing.
//
//   1. edge-preserving smoothing (curvature flow, 5 iterations): noise would otherwise
//      break the region at single voxels;
//   2. the region connected to the seed with HU in [lo, hi];
//   3. a morphological opening (ball of radius 1 voxel) cuts thin leaks into neighbours;
//   4. the largest connected component is kept;
//   5. holes (enclosed background, e.g. vessels outside the window) are filled.
#include <Eigen/Core>
#include <vector>

#include "organfit/geometry/image_geometry.h"

namespace organfit::segmentation {

struct SeedOptions {
  Eigen::Vector3d seed_mm = Eigen::Vector3d::Zero();  ///< patient coordinates (LPS)
  double hu_low = 0, hu_high = 0;                     ///< window, HU
  int smoothing_iterations = 5;
  int opening_radius_voxels = 1;
};

/// Segments on a CT given as HU values (i fastest) on `geometry`. Throws InputError on
/// a seed outside the CT, a seed whose (smoothed) HU is outside the window, or an
/// empty window.
geometry::LabelVolume segment_from_seed(const geometry::ImageGeometry& geometry, const std::vector<float>& hu,
                                        const SeedOptions& options);

}  // namespace organfit::segmentation
