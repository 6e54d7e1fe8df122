// BlockMaxima: the bound over a box is at least the largest value in it and at most the
// grid's largest; over the whole grid it is the largest; a box within one block of the
// finest level reads that block alone.
#include "organfit/geometry/block_maxima.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <limits>
#include <random>

namespace organfit::geometry {
namespace {

TEST(BlockMaxima, BoundsTheLargestValueOverAnyBox) {
  const std::array<int, 3> size = {23, 9, 17};  // not multiples of the blocks' sides
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> u(-5, 5);
  std::vector<double> value(static_cast<size_t>(size[0] * size[1] * size[2]));
  for (double& v : value)
    v = u(rng);
  auto at = [&](int i, int j, int k) {
    return value[static_cast<size_t>(i + size[0] * (j + size[1] * k))];
  };
  const Eigen::Vector3i dims = BlockMaxima::finest_dims(size);
  EXPECT_EQ(dims, Eigen::Vector3i(6, 3, 5));
  std::vector<double> finest(static_cast<size_t>(dims.prod()),
                             -std::numeric_limits<double>::infinity());
  for (int k = 0; k < size[2]; ++k)
    for (int j = 0; j < size[1]; ++j)
      for (int i = 0; i < size[0]; ++i) {
        double& m = finest[static_cast<size_t>(i / 4 + dims.x() * (j / 4 + dims.y() * (k / 4)))];
        m = std::max(m, at(i, j, k));
      }
  const BlockMaxima blocks(size, finest);
  const double largest = *std::max_element(value.begin(), value.end());
  EXPECT_EQ(blocks.largest(), largest);
  EXPECT_EQ(blocks.over({0, 0, 0}, {22, 8, 16}), largest);
  EXPECT_EQ(blocks.over({-3, -3, -3}, {40, 40, 40}), largest);  // clamped to the grid
  EXPECT_EQ(blocks.over({5, 1, 9}, {6, 2, 10}), finest[1 + 6 * (0 + 3 * 2)]);  // one block
  for (int trial = 0; trial < 500; ++trial) {
    std::array<int, 3> lo, hi;
    for (int a = 0; a < 3; ++a) {
      std::uniform_int_distribution<int> pick(0, size[a] - 1);
      lo[a] = pick(rng), hi[a] = pick(rng);
      if (hi[a] < lo[a]) std::swap(lo[a], hi[a]);
    }
    double truth = -std::numeric_limits<double>::infinity();
    for (int k = lo[2]; k <= hi[2]; ++k)
      for (int j = lo[1]; j <= hi[1]; ++j)
        for (int i = lo[0]; i <= hi[0]; ++i)
          truth = std::max(truth, at(i, j, k));
    const double bound = blocks.over(lo, hi);
    EXPECT_GE(bound, truth);
    EXPECT_LE(bound, largest);
  }
  EXPECT_THROW(BlockMaxima(size, std::vector<double>(3)), std::invalid_argument);
}

}  // namespace
}  // namespace organfit::geometry
