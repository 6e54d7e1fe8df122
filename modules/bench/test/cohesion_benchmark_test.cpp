// The cohesion benchmark reports the keys its consumers read, with sane values.
#include "organfit/bench/cohesion_benchmark.h"

#include <gtest/gtest.h>

namespace organfit::bench {
namespace {

TEST(CohesionBenchmark, ReportsWholeFccCellsAndAPositiveCostWithoutLammps) {
  CohesionBenchOptions o;
  o.particles = 500;  // rounds to 4 * 5^3
  o.steps = 5;
  o.run_lammps = false;
  const auto j = run_cohesion_benchmark(o);
  EXPECT_EQ(j["particles"].get<long long>(), 500);
  EXPECT_EQ(j["steps"].get<long long>(), 5);
  EXPECT_EQ(j["threads"].get<int>(), 1);
  EXPECT_GT(j["us_per_particle_step"].get<double>(), 0.0);
  EXPECT_TRUE(j["ratio_vs_lammps"].is_null());
  EXPECT_GE(j["neighbour_list_builds"].get<long long>(), 1);
}

TEST(CohesionBenchmark, MissingLammpsIsReportedNotFatal) {
  CohesionBenchOptions o;
  o.particles = 256;
  o.steps = 2;
  o.lammps_binary = "organfit-no-such-lmp";
  const auto j = run_cohesion_benchmark(o);
  EXPECT_TRUE(j["lammps_us_per_particle_step"].is_null());
  EXPECT_NE(j["lammps_note"].get<std::string>().find("not found"), std::string::npos);
}

}  // namespace
}  // namespace organfit::bench
