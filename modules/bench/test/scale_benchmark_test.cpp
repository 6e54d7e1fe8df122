// bench scale's flatness of the fit step (issue 26): which sessions count and the ratio.
#include "organfit/bench/scale_benchmark.h"

#include <gtest/gtest.h>

namespace organfit::bench {
namespace {

nlohmann::json scale_row(const std::string& name, double particles,
                         const std::vector<std::pair<int, double>>& points_and_us) {
  nlohmann::json sessions = nlohmann::json::array();
  for (const auto& [points, us] : points_and_us)
    sessions.push_back({{"points", points}, {"fit_particle_steps_per_s", 1e6 / us}});
  return {{"case", name}, {"particles", particles}, {"sessions", sessions}};
}

TEST(ScaleBenchmark, FlatnessIsTheLargestOverTheSmallestCostOfTheCountedSessions) {
  const nlohmann::json cases = {scale_row("prostate", 923, {{87, 0.10}}),
                                scale_row("gtv", 7021, {{87, 0.20}}),
                                scale_row("lung", 53135, {{87, 0.16}}),
                                scale_row("million", 1007585, {{87, 0.22}, {10000, 0.24}})};
  const nlohmann::json f = fit_step_flatness(cases, 5000);
  ASSERT_FALSE(f.is_null());
  ASSERT_EQ(f["sessions"].size(), 4u);  // the prostate's 923 particles do not count
  EXPECT_EQ(f["sessions"][0]["case"], "gtv");
  EXPECT_NEAR(f["sessions"][3]["us_per_particle_step"].get<double>(), 0.24, 1e-12);
  EXPECT_EQ(f["sessions"][3]["points"], 10000);
  EXPECT_NEAR(f["largest_over_smallest"].get<double>(), 0.24 / 0.16, 1e-12);
  EXPECT_DOUBLE_EQ(f["limit"].get<double>(), kFlatLimit);
  EXPECT_FALSE(f["met"].get<bool>());  // 1.5 > 1.3

  const nlohmann::json flat = {scale_row("lung", 53135, {{87, 0.20}}),
                               scale_row("million", 1007585, {{87, 0.25}})};
  EXPECT_NEAR(fit_step_flatness(flat, 5000)["largest_over_smallest"].get<double>(), 1.25, 1e-12);
  EXPECT_TRUE(fit_step_flatness(flat, 5000)["met"].get<bool>());
}

TEST(ScaleBenchmark, FlatnessNeedsTwoCountedSessions) {
  const nlohmann::json one = {scale_row("prostate", 923, {{87, 0.10}}),
                              scale_row("lung", 53135, {{87, 0.16}})};
  EXPECT_TRUE(fit_step_flatness(one, 5000).is_null());
  // A session whose steps took no measurable time has no cost to compare.
  const nlohmann::json idle = {
      scale_row("lung", 53135, {{87, 0.16}}),
      {{"case", "million"},
       {"particles", 1007585},
       {"sessions", {{{"points", 87}, {"fit_particle_steps_per_s", 0.0}}}}}};
  EXPECT_TRUE(fit_step_flatness(idle, 5000).is_null());
}

}  // namespace
}  // namespace organfit::bench
