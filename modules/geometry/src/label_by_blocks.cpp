#include "organfit/geometry/label_by_blocks.h"

#include <algorithm>
#include <array>
#include <cstdint>
#include <vector>

namespace organfit::geometry {

namespace {
/// Voxels [lo, hi] (inclusive, each axis) of a grid.
struct Block {
  std::array<int, 3> lo, hi;
};
}  // namespace

void label_by_blocks(LabelVolume& out, const IndexRange& range,
                     const std::function<BallSide(const Eigen::Vector3d&, double)>& ball,
                     const std::function<bool(const Eigen::Vector3d&)>& inside) {
  if (range.empty()) return;
  const ImageGeometry& grid = out.geometry;
  // Sets block b or halves it; writes only b's voxels.
  auto classify = [&](const Block& b, auto& self) -> void {
    // One voxel: compared coordinate by coordinate (std::array's == is a call to memcmp,
    // made for every block: a quarter of a second of a 1.5 L organ's truth).
    if (b.lo[0] == b.hi[0] && b.lo[1] == b.hi[1] && b.lo[2] == b.hi[2]) {
      out.at(b.lo[0], b.lo[1], b.lo[2]) =
          inside(grid.index_to_physical(Eigen::Vector3d(b.lo[0], b.lo[1], b.lo[2]))) ? 1 : 0;
      return;
    }
    const Eigen::Vector3d centre = grid.index_to_physical(
        0.5 * Eigen::Vector3d(b.lo[0] + b.hi[0], b.lo[1] + b.hi[1], b.lo[2] + b.hi[2]));
    Eigen::Vector3d extent;
    for (int d = 0; d < 3; ++d)
      extent[d] = (b.hi[d] - b.lo[d]) * grid.spacing_mm[d];
    const BallSide side = ball(centre, 0.5 * extent.norm());  // the direction is orthonormal
    if (side != BallSide::unknown) {
      const std::uint8_t label = side == BallSide::inside ? 1 : 0;
      for (int k = b.lo[2]; k <= b.hi[2]; ++k)
        for (int j = b.lo[1]; j <= b.hi[1]; ++j)
          std::fill_n(&out.at(b.lo[0], j, k), b.hi[0] - b.lo[0] + 1, label);
      return;
    }
    int split[3][2][2], parts[3];  // each axis longer than a voxel halved
    for (int a = 0; a < 3; ++a) {
      const int mid = (b.lo[a] + b.hi[a]) / 2;
      parts[a] = b.lo[a] == b.hi[a] ? 1 : 2;
      split[a][0][0] = b.lo[a], split[a][0][1] = parts[a] == 1 ? b.hi[a] : mid;
      split[a][1][0] = mid + 1, split[a][1][1] = b.hi[a];
    }
    for (int pk = 0; pk < parts[2]; ++pk)
      for (int pj = 0; pj < parts[1]; ++pj)
        for (int pi = 0; pi < parts[0]; ++pi)
          self(Block{{split[0][pi][0], split[1][pj][0], split[2][pk][0]},
                     {split[0][pi][1], split[1][pj][1], split[2][pk][1]}},
               self);
  };
  constexpr int kTop = 16;  // voxels a side of the coarsest blocks
  std::vector<Block> tops;
  for (int k = range.lo[2]; k <= range.hi[2]; k += kTop)
    for (int j = range.lo[1]; j <= range.hi[1]; j += kTop)
      for (int i = range.lo[0]; i <= range.hi[0]; i += kTop)
        tops.push_back(
            Block{{i, j, k},
                  {std::min(i + kTop - 1, range.hi[0]), std::min(j + kTop - 1, range.hi[1]),
                   std::min(k + kTop - 1, range.hi[2])}});
  const long n = static_cast<long>(tops.size());
#pragma omp parallel for schedule(dynamic, 1)
  for (long t = 0; t < n; ++t)
    classify(tops[static_cast<size_t>(t)], classify);
}

}  // namespace organfit::geometry
