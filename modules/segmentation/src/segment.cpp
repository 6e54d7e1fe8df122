// Eigen side of the segmentation: converts to plain images and calls the ITK side.
#include "organfit/segmentation/segment.h"

#include <fmt/format.h>

#include <algorithm>
#include <array>
#include <cmath>

#include "organfit/itkbridge/itk_images.h"
#include "organfit/segmentation/seeded_region.h"
#include "organfit/support/error.h"

namespace organfit::segmentation {

SeededOrgan segment_from_seed(const geometry::ImageGeometry& geometry, const std::vector<float>& hu,
                              const SeedOptions& o) {
  if (!(o.search_box_mm >= 0)) throw InputError("segment: the search box must be >= 0 mm");
  PlainSeedOptions p;
  for (int d = 0; d < 3; ++d)
    p.seed_mm[d] = o.seed_mm[d];
  p.hu_low = o.hu_low;
  p.hu_high = o.hu_high;
  p.smoothing_iterations = o.smoothing_iterations;
  p.opening_radius_voxels = o.opening_radius_voxels;
  // The box in voxels around the seed, clipped to the CT (the whole CT when 0, or when
  // the seed is outside: seeded_region says so).
  const Eigen::Vector3d seed_index = geometry.physical_to_index(o.seed_mm);
  std::array<int, 3> lo{0, 0, 0},
      hi{geometry.size[0] - 1, geometry.size[1] - 1, geometry.size[2] - 1};
  const bool seed_inside =
      (seed_index.array() > -0.5).all() &&
      (seed_index.array() <
       Eigen::Array3d(geometry.size[0], geometry.size[1], geometry.size[2]) - 0.5)
          .all();
  if (o.search_box_mm > 0 && seed_inside) {
    for (int d = 0; d < 3; ++d) {
      const int half = static_cast<int>(std::ceil(0.5 * o.search_box_mm / geometry.spacing_mm[d]));
      const int c = static_cast<int>(std::lround(seed_index[d]));
      lo[d] = std::max(0, c - half), hi[d] = std::min(geometry.size[d] - 1, c + half);
    }
  }
  geometry::ImageGeometry box = geometry;
  for (int d = 0; d < 3; ++d)
    box.size[d] = hi[d] - lo[d] + 1;
  box.origin_mm = geometry.index_to_physical(Eigen::Vector3d(lo[0], lo[1], lo[2]));
  std::vector<float> box_hu(static_cast<size_t>(box.voxel_count()));
  for (int k = 0; k < box.size[2]; ++k)
    for (int j = 0; j < box.size[1]; ++j) {
      const auto from = hu.begin() + geometry.linear_index(lo[0], lo[1] + j, lo[2] + k);
      std::copy(from, from + box.size[0], box_hu.begin() + box.linear_index(0, j, k));
    }
  const geometry::LabelVolume found =
      itkbridge::from_plain(seeded_region({itkbridge::to_plain(box), std::move(box_hu)}, p));

  SeededOrgan out{geometry::LabelVolume(geometry), {}};
  bool at_edge = false;
  for (int k = 0; k < box.size[2]; ++k)
    for (int j = 0; j < box.size[1]; ++j)
      for (int i = 0; i < box.size[0]; ++i) {
        if (!found.at(i, j, k)) continue;
        out.mask.at(lo[0] + i, lo[1] + j, lo[2] + k) = 1;
        const int at[3] = {lo[0] + i, lo[1] + j, lo[2] + k}, in[3] = {i, j, k};
        for (int d = 0; d < 3; ++d)  // an edge of the box that is not an edge of the CT
          at_edge = at_edge || (in[d] == 0 && at[d] > 0) ||
                    (in[d] == box.size[d] - 1 && at[d] < geometry.size[d] - 1);
      }
  if (at_edge)
    out.warnings.push_back(
        fmt::format("segment: the organ reaches the edge of the {:.0f} mm search box around the "
                    "seed: it may be cut there (a larger box, or a narrower HU window)",
                    o.search_box_mm));
  return out;
}

}  // namespace organfit::segmentation
