// Issue 3's skeleton criterion, on a small elongated body in a fluid-like state.
#include "organfit/bench/skeleton_benchmark.h"

#include <gtest/gtest.h>

namespace organfit::bench {
namespace {

TEST(SkeletonInFluidState, KeepsTheShapeWithSkeletonAndRoundsUpWithout) {
  SkeletonBenchOptions o;  // LJ 12-6 at kT = 0.7 E0: a liquid (triple point near 0.62-0.69)
  o.size_x_mm = 30;
  o.size_yz_mm = 12;
  o.temperature = 0.7;
  o.steps = 4000;
  const auto r = run_skeleton_benchmark(o);
  const double ar0 = r["aspect_ratio_start"].get<double>();
  const auto& with = r["with_skeleton"];
  const auto& without = r["without_skeleton"];
  EXPECT_GT(ar0, 2.2);
  EXPECT_LT(with["msd_to_start_r0"].get<double>(), 0.25);
  EXPECT_NEAR(with["aspect_ratio_end"].get<double>(), ar0, 0.05 * ar0);
  EXPECT_EQ(with["components"].get<int>(), 1);
  EXPECT_LT(without["aspect_ratio_end"].get<double>(), 0.7 * ar0);
  EXPECT_GT(without["msd_to_start_r0"].get<double>(), 0.5);
}

}  // namespace
}  // namespace organfit::bench
