// The LJ law of eq. 1-4: analytic values, F = -dE/dr, floor and cutoff behaviour.
#include "organfit/particles/cohesion.h"

#include <gtest/gtest.h>

#include <cmath>

namespace organfit::particles {
namespace {

TEST(CohesionLaw, RMinAndFMaxMatchTheAnalyticCheckValues) {
  // METHOD.md s.2: E0 = 1, r0 = 1.
  EXPECT_NEAR(cohesion_r_min(6, 12, 1.0), 1.10868, 5e-6);
  EXPECT_NEAR(cohesion_f_max(1.0, 6, 12, 1.0), 2.68990, 5e-6);
  EXPECT_NEAR(cohesion_r_min(4, 8, 1.0), 1.15829, 5e-6);
  EXPECT_NEAR(cohesion_f_max(1.0, 4, 8, 1.0), 1.70536, 5e-6);
}

TEST(CohesionLaw, FMaxScalesAsE0OverR0AndIsTheLargestPull) {
  EXPECT_NEAR(cohesion_f_max(3.0, 6, 12, 2.0), 3.0 / 2.0 * 2.68990, 5e-5);
  CohesionParams p;
  p.r0_mm = 2.0;
  p.cutoff_r0 = 3.0;
  const LennardJones law(p);
  // r_min is where the attraction peaks: LJ' = 0 there, and no r pulls harder.
  EXPECT_NEAR(law.bare_force_derivative(law.r_min()), 0.0, 1e-9);
  for (double r = 1.0 * p.r0_mm; r < law.cutoff(); r += 0.001) {
    EXPECT_GE(law.force(r), -law.f_max() - 1e-12) << r;
  }
}

TEST(CohesionLaw, ZeroAtR0RepulsiveBelowAttractiveAboveWellDepthE0) {
  CohesionParams p;
  p.E0 = 2.5;
  p.r0_mm = 3.0;
  const LennardJones law(p);
  EXPECT_NEAR(law.force(3.0), 0.0, 1e-12);
  EXPECT_GT(law.force(2.9), 0.0);
  EXPECT_LT(law.force(3.1), 0.0);
  EXPECT_NEAR(law.bare_energy(3.0), -2.5, 1e-12);
  EXPECT_NEAR(law.stiffness(), 6 * 12 * 2.5 / 9.0, 1e-12);
  EXPECT_NEAR(-law.bare_force_derivative(3.0), law.stiffness(), 1e-9);
}

class ForceIsMinusEnergyGradient : public ::testing::TestWithParam<std::pair<int, int>> {};

TEST_P(ForceIsMinusEnergyGradient, ByCentralDifferencesAcrossFloorAndWell) {
  CohesionParams p;
  p.m = GetParam().first;
  p.n = GetParam().second;
  p.r0_mm = 1.7;
  const LennardJones law(p);
  for (double r = 0.05 * p.r0_mm; r < 0.99 * law.cutoff(); r *= 1.013) {
    const double h = 1e-6 * r;
    const double de = (law.energy(r + h) - law.energy(r - h)) / (2 * h);
    EXPECT_NEAR(law.force(r), -de, 1e-5 * (1 + std::abs(law.force(r)))) << "r = " << r;
  }
}

INSTANTIATE_TEST_SUITE_P(Exponents, ForceIsMinusEnergyGradient,
                         ::testing::Values(std::make_pair(6, 12), std::make_pair(4, 8),
                                           std::make_pair(12, 24), std::make_pair(20, 40),
                                           std::make_pair(5, 9)));

TEST(CohesionLaw, FloorKeepsCoincidentPairsFiniteAndContinuous) {
  CohesionParams p;
  p.m = 20;
  p.n = 40;
  const LennardJones law(p);
  EXPECT_TRUE(std::isfinite(law.force(0.0)));
  EXPECT_TRUE(std::isfinite(law.energy(0.0)));
  EXPECT_GT(law.force(0.0), law.force(law.floor_distance()));
  const double rf = law.floor_distance();
  EXPECT_NEAR(law.force(rf * (1 - 1e-12)), law.force(rf * (1 + 1e-12)), 1e-6 * law.force(rf));
}

TEST(CohesionLaw, EnergyShiftedToZeroAtCutoffAndNothingBeyond) {
  const LennardJones law(CohesionParams{});
  EXPECT_NEAR(law.energy(law.cutoff() * (1 - 1e-12)), 0.0, 1e-9);
  EXPECT_EQ(law.force(law.cutoff()), 0.0);
  EXPECT_EQ(law.energy(10.0), 0.0);
}

TEST(CohesionLaw, InvalidParametersAreRefusedOnCreation) {
  auto make = [](auto edit) {
    CohesionParams p;
    edit(p);
    return LennardJones(p);
  };
  EXPECT_THROW(make([](CohesionParams& p) { p.m = 12, p.n = 6; }), std::invalid_argument);
  EXPECT_THROW(make([](CohesionParams& p) { p.m = 6, p.n = 6; }), std::invalid_argument);
  EXPECT_THROW(make([](CohesionParams& p) { p.r0_mm = -1; }), std::invalid_argument);
  EXPECT_THROW(make([](CohesionParams& p) { p.E0 = 0; }), std::invalid_argument);
  EXPECT_THROW(make([](CohesionParams& p) { p.cutoff_r0 = 1.05; }), std::invalid_argument);
  EXPECT_THROW(make([](CohesionParams& p) { p.floor_r0 = 1.5; }), std::invalid_argument);
}

TEST(Ipow, ExactIntegerPowers) {
  EXPECT_EQ(ipow(2.0, 10), 1024.0);
  EXPECT_EQ(ipow(3.0, 0), 1.0);
  EXPECT_DOUBLE_EQ(ipow(1.1, 41), std::pow(1.1, 41));
}

}  // namespace
}  // namespace organfit::particles
