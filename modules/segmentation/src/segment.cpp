// Eigen side of the segmentation: converts to plain images and calls the ITK side.
#include "organfit/segmentation/segment.h"

#include "organfit/itkbridge/itk_images.h"
#include "organfit/segmentation/seeded_region.h"

namespace organfit::segmentation {

geometry::LabelVolume segment_from_seed(const geometry::ImageGeometry& geometry, const std::vector<float>& hu,
                                        const SeedOptions& o) {
  PlainSeedOptions p;
  for (int d = 0; d < 3; ++d) p.seed_mm[d] = o.seed_mm[d];
  p.hu_low = o.hu_low;
  p.hu_high = o.hu_high;
  p.smoothing_iterations = o.smoothing_iterations;
  p.opening_radius_voxels = o.opening_radius_voxels;
  return itkbridge::from_plain(seeded_region({itkbridge::to_plain(geometry), hu}, p));
}

}  // namespace organfit::segmentation
