#include "organfit/fitting/robust.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <random>

namespace organfit::fitting {
namespace {

TEST(OutlierCutoff, MedianPlusScaledMad) {
  // median 3, |v - 3| = {2, 1, 0, 1, 97}: MAD 1.
  EXPECT_NEAR(outlier_cutoff({1, 2, 3, 4, 100}, 3.0), 3.0 + 3 * 1.4826, 1e-12);
  EXPECT_TRUE(std::isinf(outlier_cutoff({}, 3.0)));
  EXPECT_NEAR(outlier_cutoff({5, 5, 5, 5}, 2.0, 0.5), 5.0 + 2 * 1.4826 * 0.5, 1e-12);
}

std::vector<int> brute_force_nearest(const std::vector<Eigen::Vector3d>& p, int i, int k) {
  std::vector<std::pair<double, int>> d;
  for (int j = 0; j < static_cast<int>(p.size()); ++j)
    if (j != i) d.push_back({(p[j] - p[i]).squaredNorm(), j});
  std::sort(d.begin(), d.end());
  std::vector<int> out;
  for (int q = 0; q < k && q < static_cast<int>(d.size()); ++q)
    out.push_back(d[q].second);
  return out;
}

TEST(KNearest, EqualsBruteForceOnClusteredFlatAndFarSets) {
  std::mt19937 rng(5);
  std::normal_distribution<double> g;
  std::vector<std::vector<Eigen::Vector3d>> sets(3);
  for (int i = 0; i < 300; ++i)  // a cloud, a flat sheet, a cloud with far outliers
    sets[0].emplace_back(10 * g(rng), 10 * g(rng), 10 * g(rng)),
        sets[1].emplace_back(10 * g(rng), 10 * g(rng), 0.0),
        sets[2].emplace_back(g(rng), g(rng), g(rng));
  sets[2].emplace_back(500, 0, 0), sets[2].emplace_back(0, -480, 0);
  for (const auto& p : sets) {
    const auto nn = k_nearest(p, 6);
    ASSERT_EQ(nn.size(), p.size());
    for (int i = 0; i < static_cast<int>(p.size()); ++i)
      EXPECT_EQ(nn[i], brute_force_nearest(p, i, 6)) << "point " << i;
  }
  // Fewer points than k: all the others; coincident points: each other.
  const std::vector<Eigen::Vector3d> three(3, Eigen::Vector3d(1, 2, 3));
  EXPECT_EQ(k_nearest(three, 8)[0], (std::vector<int>{1, 2}));
  EXPECT_TRUE(k_nearest({Eigen::Vector3d::Zero()}, 4)[0].empty());
}

TEST(NormalisedMedianTest, FlagsAnIsolatedJumpButNotACoherentStep) {
  // Values along a line: 0 with noise, a coherent step to 5 from index 20 on, and one
  // isolated spike of 5 at index 8.
  std::vector<Eigen::Vector3d> p;
  std::vector<double> v;
  std::mt19937 rng(2);
  std::normal_distribution<double> noise(0, 0.3);
  for (int i = 0; i < 40; ++i)
    p.emplace_back(i, 0, 0), v.push_back((i >= 20 ? 5.0 : 0.0) + noise(rng));
  v[8] = 5.0;
  const auto nn = k_nearest(p, 6);
  const std::vector<char> use(v.size(), 1);
  const std::vector<char> out = normalised_median_test(v, nn, use, 3.0, 0.5);
  for (int i = 0; i < 40; ++i)
    EXPECT_EQ(out[i], i == 8) << "point " << i;
  // Neighbouring spikes support each other: two are still outliers by default (each has
  // one supporter, two are asked), not when one supporter is enough; three are a feature.
  v[9] = 5.0;
  const std::vector<char> pair = normalised_median_test(v, nn, use, 3.0, 0.5);
  EXPECT_TRUE(pair[8] && pair[9]);
  const std::vector<char> pair_one = normalised_median_test(v, nn, use, 3.0, 0.5, 1);
  EXPECT_FALSE(pair_one[8] || pair_one[9]);
  v[7] = 5.0;
  const std::vector<char> triple = normalised_median_test(v, nn, use, 3.0, 0.5);
  EXPECT_FALSE(triple[7] || triple[8] || triple[9]);
  // Left out of the neighbourhoods, the spike no longer counts; with too few neighbours
  // left no point is tested.
  std::vector<char> few(v.size(), 0);
  few[0] = few[1] = few[2] = 1;
  EXPECT_EQ(normalised_median_test(v, nn, few, 3.0, 0.5), std::vector<char>(v.size(), 0));
}

}  // namespace
}  // namespace organfit::fitting
