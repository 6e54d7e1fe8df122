#pragma once
// The ITK side of segment.h, on plain images (no Eigen: see itkbridge/plain_image.h).
#include <array>

#include "organfit/itkbridge/plain_image.h"

namespace organfit::segmentation {

struct PlainSeedOptions {
  std::array<double, 3> seed_mm{0, 0, 0};
  double hu_low = 0, hu_high = 0;
  int smoothing_iterations = 5;
  int opening_radius_voxels = 1;
};

itkbridge::PlainMask seeded_region(const itkbridge::PlainFloatImage& hu,
                                   const PlainSeedOptions& options);

}  // namespace organfit::segmentation
