// NeighbourList: the half list holds every pair closer than cutoff + skin exactly once,
// whatever the geometry (flat, thin, clustered with a far outlier, on cell boundaries).
#include "organfit/particles/neighbour_list.h"

#include <gtest/gtest.h>
#include <omp.h>

#include <random>
#include <set>
#include <utility>

#include "test_systems.h"

namespace organfit::particles {
namespace {

using PairSet = std::set<std::pair<int, int>>;

/// The pairs of the list, as particle indices (i < j); fails on a pair listed twice.
PairSet listed_pairs(const NeighbourList& list) {
  PairSet pairs;
  const auto& order = list.order();
  for (int s = 0; s < list.size(); ++s)
    for (int k = list.first()[s]; k < list.first()[s + 1]; ++k) {
      const int i = order[s], j = order[list.neighbours()[k]];
      EXPECT_NE(i, j);
      const bool inserted = pairs.insert({std::min(i, j), std::max(i, j)}).second;
      EXPECT_TRUE(inserted) << "pair " << i << "-" << j << " listed twice";
    }
  return pairs;
}

PairSet all_pairs_within(const Eigen::Matrix3Xd& x, double reach) {
  PairSet pairs;
  for (int i = 0; i < x.cols(); ++i)
    for (int j = i + 1; j < x.cols(); ++j)
      if ((x.col(i) - x.col(j)).squaredNorm() < reach * reach) pairs.insert({i, j});
  return pairs;
}

void expect_exact_half_list(const Eigen::Matrix3Xd& x, double cutoff, double skin) {
  NeighbourList list(cutoff, skin);
  ASSERT_TRUE(list.update(x));
  const PairSet expected = all_pairs_within(x, cutoff + skin);
  const PairSet got = listed_pairs(list);
  EXPECT_EQ(got.size(), expected.size());
  EXPECT_TRUE(got == expected);
  EXPECT_EQ(list.pair_count(), static_cast<long long>(expected.size()));
  // Blocks of one colour cover disjoint slot ranges, and all blocks cover every slot.
  long long covered = 0;
  for (const auto& colour : list.colours())
    for (int b : colour)
      covered += list.block_end()[b] - list.block_begin()[b];
  EXPECT_EQ(covered, x.cols());
}

TEST(NeighbourList, ListsExactlyThePairsWithinReachInARandomCloud) {
  for (unsigned seed : {1u, 2u})
    expect_exact_half_list(testing::random_cloud(2000, 20.0, 0.5, seed), 2.5, 0.3);
}

TEST(NeighbourList, ListsExactlyThePairsWithinReachOnCellBoundaries) {
  // A cubic lattice at exactly half the reach: every particle sits on a cell face.
  const double reach = 2.8, a = reach / 2;
  Eigen::Matrix3Xd x(3, 12 * 12 * 12);
  int i = 0;
  for (int k = 0; k < 12; ++k)
    for (int j = 0; j < 12; ++j)
      for (int l = 0; l < 12; ++l)
        x.col(i++) = a * Eigen::Vector3d(l, j, k);
  expect_exact_half_list(x, 2.5, 0.3);
  // Pairs at exactly the reach are not listed (strictly closer only).
  expect_exact_half_list(x, 2.5, 0.3 + 1e-9);
}

TEST(NeighbourList, ListsExactlyThePairsWithinReachInFlatAndThinBodies) {
  std::mt19937 rng(5);
  std::uniform_real_distribution<double> u(0, 30.0);
  Eigen::Matrix3Xd plane(3, 1500), line(3, 300);
  for (int i = 0; i < plane.cols(); ++i)
    plane.col(i) = Eigen::Vector3d(u(rng), u(rng), 4.0);
  for (int i = 0; i < line.cols(); ++i)
    line.col(i) = Eigen::Vector3d(1.0, u(rng), -2.0);
  expect_exact_half_list(plane, 2.5, 0.3);
  expect_exact_half_list(line, 2.5, 0.3);
}

TEST(NeighbourList, ListsExactlyThePairsWithinReachWithAFarOutlier) {
  // The outlier stretches the grid to 1e6 mm: it is coarsened, still exact.
  Eigen::Matrix3Xd x = testing::random_cloud(800, 12.0, 0.4, 9);
  x.conservativeResize(3, x.cols() + 1);
  x.col(x.cols() - 1) = Eigen::Vector3d(1e6, -3e5, 2e5);
  expect_exact_half_list(x, 2.5, 0.3);
}

TEST(NeighbourList, ListsExactlyThePairsWithinReachWhenCoincident) {
  Eigen::Matrix3Xd x = Eigen::Matrix3Xd::Constant(3, 50, 1.5);
  expect_exact_half_list(x, 2.5, 0.3);
  EXPECT_EQ(all_pairs_within(x, 2.8).size(), 50u * 49u / 2u);
}

TEST(NeighbourList, ListsExactlyThePairsWhereASlotHasHundredsOfNeighbours) {
  // More candidates for a slot than its first buffer holds (64): that slot is listed again
  // with room, alone and on threads (a cloud above the parallel size with a pile in it).
  expect_exact_half_list(Eigen::Matrix3Xd::Constant(3, 300, -4.0), 2.5, 0.3);
  Eigen::Matrix3Xd x = testing::random_cloud(9000, 34.0, 0.6, 5);
  ASSERT_GT(x.cols(), kParallelMinParticles);
  const Eigen::Index cloud = x.cols();
  x.conservativeResize(3, cloud + 200);
  for (Eigen::Index k = cloud; k < x.cols(); ++k)
    x.col(k) = x.col(cloud / 2) + 0.01 * Eigen::Vector3d(k % 5, (k / 5) % 5, k % 3);
  expect_exact_half_list(x, 2.5, 0.3);
}

TEST(NeighbourList, ListsTheSamePairsWithOneAndTwoThreads) {
  const Eigen::Matrix3Xd x = testing::random_cloud(9000, 34.0, 0.6, 4);
  ASSERT_GT(x.cols(), kParallelMinParticles);
  const int saved = omp_get_max_threads();
  omp_set_num_threads(1);
  NeighbourList one(2.5, 0.3);
  one.update(x);
  omp_set_num_threads(2);
  NeighbourList two(2.5, 0.3);
  two.update(x);
  omp_set_num_threads(saved);
  EXPECT_EQ(one.order(), two.order());
  EXPECT_EQ(one.first(), two.first());
  EXPECT_EQ(one.neighbours(), two.neighbours());
  EXPECT_TRUE(listed_pairs(one) == all_pairs_within(x, 2.8));
}

}  // namespace
}  // namespace organfit::particles
