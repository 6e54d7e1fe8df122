#pragma once
// The physical frame of a voxel grid, in patient coordinates (DICOM LPS, mm).
//
//   x_mm = origin_mm + direction * diag(spacing_mm) * index
//
// `origin_mm` is the centre of voxel (0,0,0); the columns of `direction` are the
// unit axis directions of i, j, k (a rotation, possibly with a reflection).
#include <Eigen/Core>
#include <array>
#include <cstdint>
#include <functional>
#include <vector>

#include "organfit/geometry/plain_image.h"

namespace organfit::geometry {

/// Axis-aligned box in mm.
struct Aabb {
  Eigen::Vector3d min_mm = Eigen::Vector3d::Constant(0);
  Eigen::Vector3d max_mm = Eigen::Vector3d::Constant(0);
  Eigen::Vector3d size_mm() const { return max_mm - min_mm; }
};

/// The box of the images of `box`'s 8 corners under `f` (mm in, whatever units out):
/// the image of the box itself for an affine f, a box to widen for any other.
inline Aabb image_of_box(const Aabb& box,
                         const std::function<Eigen::Vector3d(const Eigen::Vector3d&)>& f) {
  Aabb out{Eigen::Vector3d::Constant(1e300), Eigen::Vector3d::Constant(-1e300)};
  for (int c = 0; c < 8; ++c) {
    const Eigen::Vector3d corner((c & 1) ? box.max_mm.x() : box.min_mm.x(),
                                 (c & 2) ? box.max_mm.y() : box.min_mm.y(),
                                 (c & 4) ? box.max_mm.z() : box.min_mm.z());
    const Eigen::Vector3d q = f(corner);
    out.min_mm = out.min_mm.cwiseMin(q);
    out.max_mm = out.max_mm.cwiseMax(q);
  }
  return out;
}

struct ImageGeometry {
  std::array<int, 3> size{0, 0, 0};                         ///< voxels along i, j, k
  Eigen::Vector3d spacing_mm = Eigen::Vector3d::Ones();     ///< voxel size along i, j, k
  Eigen::Vector3d origin_mm = Eigen::Vector3d::Zero();      ///< centre of voxel (0,0,0)
  Eigen::Matrix3d direction = Eigen::Matrix3d::Identity();  ///< columns: axis directions

  long long voxel_count() const { return 1LL * size[0] * size[1] * size[2]; }
  double voxel_volume_mm3() const { return spacing_mm.prod(); }
  /// Linear index of (i, j, k), i fastest.
  long long linear_index(int i, int j, int k) const {
    return i + 1LL * size[0] * (j + 1LL * size[1] * k);
  }
  /// Physical position of a (continuous) voxel index.
  Eigen::Vector3d index_to_physical(const Eigen::Vector3d& index) const {
    return origin_mm + direction * spacing_mm.cwiseProduct(index);
  }
  /// Continuous voxel index of a physical position.
  Eigen::Vector3d physical_to_index(const Eigen::Vector3d& p_mm) const;
  /// Bounding box of the voxel centres, in mm.
  Aabb bounds_mm() const;
};

/// A box of voxel indices, inclusive per axis; empty when lo > hi on some axis.
struct IndexRange {
  std::array<int, 3> lo{0, 0, 0}, hi{-1, -1, -1};
  bool empty() const { return lo[0] > hi[0] || lo[1] > hi[1] || lo[2] > hi[2]; }
};

/// Every voxel of `grid`.
inline IndexRange whole_range(const ImageGeometry& grid) {
  return {{0, 0, 0}, {grid.size[0] - 1, grid.size[1] - 1, grid.size[2] - 1}};
}

/// The voxels of `grid` whose centres may lie in the physical `box` (any direction
/// matrix): the index bounding box of its 8 corners (floor, ceil), widened by `pad`
/// voxels and clamped to the grid.
IndexRange index_range(const ImageGeometry& grid, const Aabb& box, int pad = 0);

/// A binary or multi-label mask on an image grid (0 = background).
struct LabelVolume {
  ImageGeometry geometry;
  std::vector<std::uint8_t> labels;  ///< voxel_count() values, i fastest

  explicit LabelVolume(const ImageGeometry& g = {})
      : geometry(g), labels(static_cast<size_t>(g.voxel_count()), 0) {}
  std::uint8_t at(int i, int j, int k) const {
    return labels[static_cast<size_t>(geometry.linear_index(i, j, k))];
  }
  std::uint8_t& at(int i, int j, int k) {
    return labels[static_cast<size_t>(geometry.linear_index(i, j, k))];
  }
  /// Label at a physical point, nearest voxel; 0 outside the grid.
  std::uint8_t at_physical(const Eigen::Vector3d& p_mm) const;
  long long count(std::uint8_t label) const;
  /// The index box of the voxels of `label` (empty(), lo = size and hi = -1, when none).
  IndexRange range(std::uint8_t label) const;
  double volume_mm3(std::uint8_t label) const {
    return static_cast<double>(count(label)) * geometry.voxel_volume_mm3();
  }
};

/// Trilinear interpolation's corners: calls visit(di, dj, dk, weight) for the eight
/// corners (di, dj, dk in {0, 1}) of the cell whose base corner is at fraction `f` (each
/// coordinate in [0, 1]) below the point; the weights sum to 1.
template <class Visit>
void for_each_trilinear_corner(const Eigen::Vector3d& f, Visit&& visit) {
  for (int c = 0; c < 8; ++c) {
    const int di = c & 1, dj = (c >> 1) & 1, dk = (c >> 2) & 1;
    visit(di, dj, dk,
          (di ? f.x() : 1 - f.x()) * (dj ? f.y() : 1 - f.y()) * (dk ? f.z() : 1 - f.z()));
  }
}

/// The same grid and mask as plain arrays (plain_image.h), exactly, and back.
PlainGeometry to_plain(const ImageGeometry& g);
ImageGeometry from_plain(const PlainGeometry& g);
PlainMask to_plain(const LabelVolume& labels);
LabelVolume from_plain(const PlainMask& mask);

}  // namespace organfit::geometry
