// FIRE minimisation: the pair's minimum, a block's rest at the damped relaxation's energy
// in fewer steps, determinism across threads, refused options.
#include "organfit/particles/fire.h"

#include <gtest/gtest.h>

#include <random>

#include "organfit/particles/integrator.h"
#include "test_systems.h"

namespace organfit::particles {
namespace {

FireOptions fire_options(const Model& model) {
  IntegratorOptions opt;
  FireOptions fire;
  fire.time_step_s = opt.time_step_fraction * Integrator::stability_limit_s(model);
  return fire;
}

/// An fcc block at the equilibrium spacing, each particle moved by up to `jitter` r0.
State jittered_block(const LennardJones& law, double side_r0, double jitter, unsigned seed) {
  State s(fill_box(Eigen::Vector3d::Constant(side_r0 * law.r0()), Eigen::Vector3d::Zero(),
                   fcc_equilibrium_spacing(law)));
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> u(-jitter * law.r0(), jitter * law.r0());
  for (int i = 0; i < s.size(); ++i)
    for (int d = 0; d < 3; ++d)
      s.x(d, i) += u(rng);
  return s;
}

TEST(Fire, APairSettlesAtTheEquilibriumDistance) {
  CohesionParams p;
  p.r0_mm = 2.0;
  Model model = testing::cohesion_model(2, p);
  State s(Positions(3, 2));
  s.x.col(0) = Eigen::Vector3d::Zero();
  s.x.col(1) = Eigen::Vector3d(1.4 * p.r0_mm, 0.3, -0.2);
  const FireResult r = minimise_fire(model, s, fire_options(model), 10000, 1e-10);
  EXPECT_TRUE(r.settled);
  EXPECT_LE(r.rms_force, 1e-10);
  EXPECT_NEAR((s.x.col(1) - s.x.col(0)).norm(), p.r0_mm, 1e-9);
  EXPECT_EQ(s.v.cwiseAbs().maxCoeff(), 0.0);  // at rest when it returns
  // No net force, no drift of the pair's centre.
  EXPECT_NEAR((s.x.col(0) + s.x.col(1)).x(), 1.4 * p.r0_mm, 1e-12);
}

TEST(Fire, RelaxesABlockToTheDampedRelaxationsRestInFewerSteps) {
  // The same jittered block relaxed by damped dynamics to its kinetic-energy tolerance,
  // and by FIRE to the rms force that tolerance means under the same damping (the model
  // stage's rule): FIRE ends no higher in energy, with no more force, in fewer steps.
  CohesionParams p;
  const LennardJones law(p);
  const State start = jittered_block(law, 6, 0.05, 3);
  Model model = testing::cohesion_model(start.size(), p);
  IntegratorOptions opt;
  opt.damping = 2 * 0.5 * std::sqrt(law.stiffness() / (p.n - p.m) * model.mass());
  opt.length_scale_mm = p.r0_mm;
  const double ke_tolerance = 1e-6;
  State damped = start;
  const RelaxResult dr = relax(model, damped, opt, 100000, ke_tolerance);
  ASSERT_TRUE(dr.settled);
  State fired = start;
  const double force_tolerance = opt.damping * std::sqrt(2 * ke_tolerance / model.mass());
  const FireResult fr = minimise_fire(model, fired, fire_options(model), 100000, force_tolerance);
  ASSERT_TRUE(fr.settled);
  Forces f;
  const double e_damped = model.compute_forces(damped, f, true);
  const double rms_damped = std::sqrt(f.squaredNorm() / start.size());
  const double e_fired = model.compute_forces(fired, f, true);
  EXPECT_LE(fr.rms_force, force_tolerance);
  EXPECT_NEAR(std::sqrt(f.squaredNorm() / start.size()), fr.rms_force, 1e-15);
  EXPECT_LE(e_fired, e_damped + 1e-6 * std::abs(e_damped));
  EXPECT_LT(fr.steps, dr.steps) << "damped rms force " << rms_damped;
  EXPECT_EQ(fr.capped_moves, 0);
}

TEST(Fire, TheSameWithOneAndTwoThreads) {
  CohesionParams p;
  const LennardJones law(p);
  EXPECT_EQ(testing::one_and_two_threads_differ_by([&] {
              State s = jittered_block(law, 15, 0.05, 4);  // above the serial threshold
              EXPECT_GT(s.size(), kParallelMinParticles);
              Model model = testing::cohesion_model(s.size(), p);
              minimise_fire(model, s, fire_options(model), 60, 0.0);
              return s.x;
            }),
            0.0);
}

TEST(Fire, InvalidOptionsAreRefused) {
  Model model = testing::cohesion_model(2, CohesionParams{});
  State s(Positions::Zero(3, 2));
  s.x(0, 1) = 1.0;
  FireOptions bad = fire_options(model);
  bad.time_step_s = 0;
  EXPECT_THROW(minimise_fire(model, s, bad, 10, 0.0), std::invalid_argument);
  bad = fire_options(model);
  bad.time_step_shrink = 1.0;
  EXPECT_THROW(minimise_fire(model, s, bad, 10, 0.0), std::invalid_argument);
  bad = fire_options(model);
  bad.alpha_start = 0;
  EXPECT_THROW(minimise_fire(model, s, bad, 10, 0.0), std::invalid_argument);
  EXPECT_THROW(minimise_fire(model, s, fire_options(model), 10, -1.0), std::invalid_argument);
}

}  // namespace
}  // namespace organfit::particles
