#pragma once
// A bound from above on the largest of a grid's values over a box of its voxels: the
// largest over the blocks (4, 8, 16... voxels a side) that cover the box, read at the
// finest level whose blocks are at least the box's size (at most 2 a side: 8 read). For
// bounds that hold where a ball lies rather than over a whole grid: a signed distance's
// slope (steep only where a thick-sliced mask's slices step), a displacement's gradient
// (large only where it falls away from the organ).
#include <Eigen/Core>
#include <algorithm>
#include <array>
#include <vector>

namespace organfit::geometry {

class BlockMaxima {
 public:
  static constexpr int kFinest = 4;  ///< voxels a side of the finest blocks

  /// The finest blocks' counts along each axis for a grid of `size` voxels.
  static Eigen::Vector3i finest_dims(const std::array<int, 3>& size);

  BlockMaxima() = default;
  /// From the maxima over the finest blocks of a grid of `size` voxels (block (a, b, c) at
  /// a + dims.x (b + dims.y c), dims = finest_dims(size)); the coarser levels are made here.
  BlockMaxima(const std::array<int, 3>& size, std::vector<double> finest);
  /// Of value(i, j, k) at every voxel of a grid of `size` voxels (no lower than 0), called
  /// on threads: a layer of the finest blocks per thread at a time, each block written by
  /// one thread.
  template <class Value>
  static BlockMaxima of(const std::array<int, 3>& size, const Value& value) {
    const Eigen::Vector3i dims = finest_dims(size);
    std::vector<double> finest(static_cast<size_t>(dims.prod()), 0.0);
#pragma omp parallel for schedule(dynamic, 1)
    for (int kb = 0; kb < dims.z(); ++kb)
      for (int k = kb * kFinest; k < std::min(size[2], (kb + 1) * kFinest); ++k)
        for (int j = 0; j < size[1]; ++j) {
          double* row =
              finest.data() + static_cast<size_t>(dims.x()) * (j / kFinest + dims.y() * kb);
          for (int i = 0; i < size[0]; ++i)
            row[i / kFinest] = std::max(row[i / kFinest], value(i, j, k));
        }
    return BlockMaxima(size, std::move(finest));
  }

  bool empty() const {
    return levels_.empty();
  }
  /// The largest value of the grid (-infinity for an empty one).
  double largest() const;
  /// At least the largest value over voxels lo..hi (inclusive each axis, clamped to the
  /// grid), at most largest().
  double over(const std::array<int, 3>& lo, const std::array<int, 3>& hi) const;

 private:
  std::array<int, 3> size_{0, 0, 0};
  std::vector<std::vector<double>> levels_;  // level l: blocks of kFinest * 2^l voxels
  std::vector<Eigen::Vector3i> dims_;
};

}  // namespace organfit::geometry
