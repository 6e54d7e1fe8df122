// Time stepping: energy conservation, damping, stability limits, extreme cases, determinism.
#include "organfit/particles/integrator.h"

#include <gtest/gtest.h>

#include "organfit/particles/diagnostics.h"
#include "test_systems.h"

namespace organfit::particles {
namespace {

/// A relaxed-spacing fcc block of particles with small random velocities.
State warm_block(const LennardJones& law, Eigen::Vector3d size_r0, double speed, unsigned seed) {
  const double a = fcc_equilibrium_spacing(law);
  State s(fill_box(size_r0 * law.r0(), Eigen::Vector3d::Zero(), a));
  std::mt19937 rng(seed);
  std::normal_distribution<double> g(0, speed);
  for (int i = 0; i < s.size(); ++i)
    for (int d = 0; d < 3; ++d)
      s.v(d, i) = g(rng);
  s.v.colwise() -= s.v.rowwise().mean();  // no drift of the whole body
  return s;
}

double total_energy(Model& model, Integrator& integ, State& s) {
  Forces f;
  return model.compute_forces(s, f, true) + integ.kinetic_energy(s);
}

TEST(VelocityVerlet, ConservesEnergyOverTenThousandSteps) {
  CohesionParams p;
  const LennardJones law(p);
  State s = warm_block(law, {5, 5, 5}, 0.2, 1);
  Model model = testing::cohesion_model(s.size(), p);
  IntegratorOptions opt;
  opt.length_scale_mm = p.r0_mm;
  // Verlet's energy error is O(dt^2) (a bounded oscillation, no drift): at the default
  // 0.1 of the limit it oscillates by ~2% of KE; at 0.02 by 25x less.
  opt.time_step_fraction = 0.02;
  Integrator integ(model, opt);
  const double e0 = total_energy(model, integ, s);
  const double ke0 = integ.kinetic_energy(s);
  double worst = 0;
  for (int block = 0; block < 100; ++block) {
    integ.run(s, 100);
    worst = std::max(worst, std::abs(total_energy(model, integ, s) - e0));
  }
  EXPECT_EQ(integ.stats().steps, 10000);
  EXPECT_EQ(integ.stats().capped_moves, 0);
  // Stated tolerance: drift below 1% of the initial kinetic energy, 1e-4 of |E|.
  EXPECT_LT(worst, 0.01 * ke0) << "E0 = " << e0 << ", KE0 = " << ke0;
  EXPECT_LT(worst, 1e-4 * std::abs(e0));
}

TEST(DampedVerlet, TotalEnergyDecreasesMonotonically) {
  CohesionParams p;
  const LennardJones law(p);
  State s = warm_block(law, {4, 4, 4}, 0.5, 2);
  Model model = testing::cohesion_model(s.size(), p);
  IntegratorOptions opt;
  opt.damping = 0.5;
  Integrator integ(model, opt);
  double previous = total_energy(model, integ, s);
  for (int k = 0; k < 200; ++k) {
    integ.run(s, 10);
    const double e = total_energy(model, integ, s);
    EXPECT_LE(e, previous + 1e-12 * std::abs(previous)) << "after " << integ.stats().steps;
    previous = e;
  }
  EXPECT_LT(integ.kinetic_energy(s) / s.size(), 1e-6);
}

TEST(Integrator, TimeStepAtTwiceTheStabilityLimitIsRefused) {
  CohesionParams p;
  Model model = testing::cohesion_model(10, p);
  const double limit = Integrator::stability_limit_s(model);
  EXPECT_NEAR(limit, 2 * std::sqrt(1.0 / 72.0), 1e-12);  // M = 1, k = m n E0 / r0^2
  IntegratorOptions opt;
  opt.time_step_s = 2 * limit;
  EXPECT_THROW(Integrator(model, opt), std::invalid_argument);
  opt.time_step_s = 0.05 * limit;
  EXPECT_NO_THROW(Integrator(model, opt));
}

TEST(Integrator, TooLargeStepBelowTheLimitIsCaughtNeverNaN) {
  // 0.9 of the single-pair limit is unstable for a lattice (higher modes): the cap
  // must catch it and halve the step (or, without adaptation, stop with an error).
  CohesionParams p;
  const LennardJones law(p);
  for (bool adapt : {true, false}) {
    State s = warm_block(law, {4, 4, 4}, 0.1, 3);
    Model model = testing::cohesion_model(s.size(), p);
    IntegratorOptions opt;
    opt.time_step_s = 0.9 * Integrator::stability_limit_s(model);
    opt.adapt_time_step = adapt;
    Integrator integ(model, opt);
    if (adapt) {
      integ.run(s, 2000);
      EXPECT_GT(integ.stats().time_step_halvings, 0);
      EXPECT_TRUE(s.x.allFinite());
      EXPECT_EQ(connected_components(s.x, 1.5 * p.r0_mm), 1);
    } else {
      EXPECT_THROW(integ.run(s, 2000), StabilityError);
      EXPECT_TRUE(s.x.allFinite());
    }
  }
}

class StiffExponents : public ::testing::TestWithParam<std::pair<int, int>> {};

TEST_P(StiffExponents, RelaxedBlockStaysFiniteBoundedAndInOnePiece) {
  CohesionParams p;
  p.m = GetParam().first;
  p.n = GetParam().second;
  p.r0_mm = 2.0;
  const LennardJones law(p);
  State s = warm_block(law, {5, 4, 4}, 0.05, 4);
  Model model = testing::cohesion_model(s.size(), p);
  IntegratorOptions opt;
  opt.damping = 0.2;
  opt.length_scale_mm = p.r0_mm;
  Integrator integ(model, opt);
  const double e0 = total_energy(model, integ, s);
  integ.run(s, 3000);
  EXPECT_TRUE(s.x.allFinite());
  EXPECT_LE(total_energy(model, integ, s), e0 + 1e-9 * std::abs(e0));
  EXPECT_EQ(connected_components(s.x, 1.5 * p.r0_mm), 1);
}

INSTANTIATE_TEST_SUITE_P(Pairs, StiffExponents,
                         ::testing::Values(std::make_pair(6, 12), std::make_pair(12, 24),
                                           std::make_pair(20, 40)));

TEST(Integrator, TwoParticlesAtOneHundredthOfR0StayFiniteWithBoundedEnergy) {
  // The overlap stores thousands of E0 (above the well depth), so the free pair flies
  // apart: correct physics. What must hold: finite state, energy never above its start.
  for (int n : {12, 24, 40}) {
    CohesionParams p;
    p.m = n / 2;
    p.n = n;
    Positions x(3, 2);
    x << 0, 0.01, 0, 0, 0, 0;
    State s(x);
    Model model = testing::cohesion_model(2, p);
    IntegratorOptions opt;
    opt.damping = 0.5;
    Integrator integ(model, opt);
    const double e0 = total_energy(model, integ, s);
    integ.run(s, 2000);
    EXPECT_TRUE(s.x.allFinite() && s.v.allFinite());
    EXPECT_LE(total_energy(model, integ, s), e0);
    EXPECT_GT((s.x.col(0) - s.x.col(1)).norm(), p.r0_mm * 0.9) << "m,n = " << p.m << "," << p.n;
    EXPECT_GT(integ.stats().capped_moves, 0);  // the safety net acted, and was counted
  }
}

TEST(Integrator, NearlyCoincidentPairInsideABodyKeepsItInOnePiece) {
  for (int n : {12, 24, 40}) {
    CohesionParams p;
    p.m = n / 2;
    p.n = n;
    const LennardJones law(p);
    State block = warm_block(law, {6, 6, 6}, 0.0, 6);
    Positions x(3, block.size() + 1);
    x.leftCols(block.size()) = block.x;
    Eigen::Index centre = 0;  // the particle nearest the block's centroid
    (block.x.colwise() - block.x.rowwise().mean()).colwise().squaredNorm().minCoeff(&centre);
    x.col(block.size()) = block.x.col(centre) + Eigen::Vector3d(0.01 * p.r0_mm, 0, 0);
    State s(x);
    Model model = testing::cohesion_model(s.size(), p);
    IntegratorOptions opt;
    opt.damping = 1.0;
    opt.max_speed_mm_s = std::sqrt(2 * 5 * p.E0 / model.mass());  // at most 5 E0 of KE
    Integrator integ(model, opt);
    integ.run(s, 3000);
    EXPECT_TRUE(s.x.allFinite());
    EXPECT_EQ(connected_components(s.x, 1.5 * p.r0_mm), 1) << "m,n = " << p.m << "," << p.n;
  }
}

TEST(Integrator, EmptyAndSingleParticleSystemsRun) {
  CohesionParams p;
  for (int n : {0, 1}) {
    State s(Positions::Zero(3, n));
    Model model = testing::cohesion_model(n, p);
    Integrator integ(model, IntegratorOptions{});
    integ.run(s, 10);
    EXPECT_TRUE(s.x.allFinite());
  }
}

TEST(Integrator, LangevinRunIsBitIdenticalWithOneAndTwoThreads) {
  CohesionParams p;
  const LennardJones law(p);
  EXPECT_EQ(testing::one_and_two_threads_differ_by([&] {
              State s = warm_block(law, {15, 15, 15}, 0.1, 5);  // above the serial threshold
              EXPECT_GT(s.size(), kParallelMinParticles);
              Model model = testing::cohesion_model(s.size(), p);
              IntegratorOptions opt;
              opt.damping = 1.0;
              opt.temperature = 0.3;
              Integrator integ(model, opt);
              integ.run(s, 300);
              return s.x;
            }),
            0.0);
}

TEST(Integrator, InvalidOptionsAreRefused) {
  Model model = testing::cohesion_model(4, CohesionParams{});
  IntegratorOptions opt;
  opt.temperature = 1.0;  // without damping: no thermostat friction
  EXPECT_THROW(Integrator(model, opt), std::invalid_argument);
  opt = {};
  opt.damping = -1;
  EXPECT_THROW(Integrator(model, opt), std::invalid_argument);
}

}  // namespace
}  // namespace organfit::particles
