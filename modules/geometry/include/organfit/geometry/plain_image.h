#pragma once
// An image grid and a mask as plain arrays, with no Eigen: what the toolkit sides of the
// ITK and VTK bridges see. Why: ITK 5.2 bundles its own Eigen (3.3) under the same
// include guards as the system's (3.4), so a translation unit must never see both; the
// conversions from ImageGeometry and LabelVolume are in image_geometry.h.
#include <array>
#include <cstddef>
#include <cstdint>
#include <vector>

namespace organfit::geometry {

/// ImageGeometry's fields: voxels, spacing (mm), the centre of voxel (0, 0, 0) (mm,
/// patient LPS) and the axes' directions (row-major 3 x 3, column d the axis d).
struct PlainGeometry {
  std::array<int, 3> size{0, 0, 0};
  std::array<double, 3> spacing_mm{1, 1, 1};
  std::array<double, 3> origin_mm{0, 0, 0};
  std::array<double, 9> direction{1, 0, 0, 0, 1, 0, 0, 0, 1};  ///< row-major
  size_t voxel_count() const { return static_cast<size_t>(size[0]) * size[1] * size[2]; }
};

struct PlainMask {
  PlainGeometry geometry;
  std::vector<std::uint8_t> labels;  ///< i fastest
};

}  // namespace organfit::geometry
