// The fit loop's stopping rule: converged when the mean residual, its 95th percentile
// and the kinetic energy are all within tolerance; one far point does not decide; once the
// points are explained, the fit stops at the step the body comes to rest.
#include "organfit/fitting/fit.h"

#include <gtest/gtest.h>

#include <functional>
#include <limits>
#include <numeric>

namespace organfit::fitting {
namespace {

/// n particles at rest 10 mm apart along x (the first at x0_mm), no force on them, every
/// one on the skin; each test puts its points beside them.
struct ParticleRow {
  ParticleRow(int n, double rho_mm, double x0_mm = 0) : x(3, n), model(n, 1.0, rho_mm), all(n) {
    for (int i = 0; i < n; ++i)
      x.col(i) = Eigen::Vector3d(10.0 * i + x0_mm, 0, 0);
    std::iota(all.begin(), all.end(), 0);
    io.time_step_s = 1e-3;
  }
  FitResult fit(particles::State& state, const std::vector<AttractivePoint>& points,
                const FitOptions& fo,
                const std::function<void(particles::State&)>& while_reaching = nullptr) {
    return run_fit(
        model, state, io, points,
        [this](const particles::Positions&) -> const std::vector<int>& { return all; }, nullptr, fo,
        nullptr, while_reaching);
  }
  particles::Positions x;
  particles::Model model;
  std::vector<int> all;
  particles::IntegratorOptions io;
};

// Rejected points (NaN) are left out; the 95th percentile is by nearest rank: of 20
// residuals 1..20 mm, the 19th.
TEST(SummariseResiduals, LeavesOutRejectedPointsAndTakesTheNearestRank) {
  std::vector<double> r;
  for (int k = 20; k >= 1; --k)
    r.push_back(k);
  r.push_back(std::numeric_limits<double>::quiet_NaN());
  const ResidualSummary s = summarise_residuals(r);
  EXPECT_DOUBLE_EQ(s.mean_mm, 10.5);
  EXPECT_DOUBLE_EQ(s.max_mm, 20.0);
  EXPECT_DOUBLE_EQ(s.p95_mm, 19.0);
  const ResidualSummary none = summarise_residuals({std::numeric_limits<double>::quiet_NaN()});
  EXPECT_EQ(none.mean_mm, 0.0);
  EXPECT_EQ(none.p95_mm, 0.0);
}

TEST(RunFit, OneFarPointDoesNotKeepAFitFromConverging) {
  // 20 particles at rest with no force on them, a point on each one's surface (residual
  // 0) but one, 1.5 radii off (beyond the radius): the largest residual exceeds rho, the
  // 95th percentile does not.
  const double rho = 2.0;
  ParticleRow row(20, rho);
  const particles::Positions& x = row.x;
  particles::State state(x);
  std::vector<AttractivePoint> points;
  for (int i = 0; i < 20; ++i)
    points.push_back({x.col(i) + Eigen::Vector3d(0, 0, i == 7 ? 2.5 * rho : rho), 1.0});
  FitOptions fo;
  fo.record_every = 5;
  fo.max_steps = 200;
  const FitResult r = row.fit(state, points, fo);
  EXPECT_TRUE(r.converged) << r.stop_reason;
  EXPECT_NEAR(r.residual_max_mm, 1.5 * rho, 1e-12);
  EXPECT_NEAR(r.residual_p95_mm, 0.0, 1e-12);
  EXPECT_NEAR(r.residual_mean_mm, 1.5 * rho / 20, 1e-12);
  // Two such points out of 20 (10%) are beyond the 95th percentile's tolerance: no.
  points[3].p_mm = x.col(3) + Eigen::Vector3d(0, 0, 2.5 * rho);
  particles::State again(x);
  const FitResult s = row.fit(again, points, fo);
  EXPECT_FALSE(s.converged);
  EXPECT_NEAR(s.residual_p95_mm, 1.5 * rho, 1e-12);
}

TEST(RunFit, MeasuresTheVolumeOnlyOfStatesItHasNotBeenGiven) {
  // Particles with no force on them, points 1 mm beyond their surface (the fit runs to
  // its step budget); "volume" the sum of x (mm), its calls counted. Given the start's,
  // the first row (the start) is not measured again, and the last row's measure is the
  // state the fit ends in.
  const double rho = 2.0;
  ParticleRow row(10, rho, 10);
  const particles::Positions& x = row.x;
  std::vector<AttractivePoint> points;
  for (int i = 0; i < 10; ++i)
    points.push_back({x.col(i) + Eigen::Vector3d(rho + 1, 0, 0), 1.0});
  int calls = 0;
  FitOptions fo;
  fo.record_every = 5;
  fo.max_steps = 20;
  fo.volume_every_rows = 1;
  fo.volume = [&calls](const particles::Positions& p) { return ++calls, p.row(0).sum(); };
  fo.volume_at_start_mm3 = x.row(0).sum();
  particles::State state(x);
  const FitResult r = row.fit(state, points, fo);
  ASSERT_EQ(r.history.size(), 5u);  // steps 0, 5, 10, 15, 20
  EXPECT_EQ(calls, 4);
  EXPECT_EQ(r.history[0].volume_change_pct, 0.0);
  EXPECT_DOUBLE_EQ(r.volume_at_end_mm3, state.x.row(0).sum());
  // Not given: the start is measured once (the first row's change is still 0).
  calls = 0;
  fo.volume_at_start_mm3 = 0;
  particles::State again(x);
  row.fit(again, points, fo);
  EXPECT_EQ(calls, 5);
}

TEST(RunFit, AdjustsTheModelBetweenRowsOnlyUntilThePointsAreExplained) {
  // Particles with no force on them, points 1 mm beyond their surface; while_reaching
  // moves every particle 0.3 mm towards its point. Rows at steps 0, 5, 10: residuals 1.0,
  // 0.7, 0.4 mm; 0.4 is within the 0.5 mm tolerance, so the points are explained at step
  // 10 and the model is left alone from then on (the kinetic tolerance is never met here:
  // the fit runs to its step budget).
  const double rho = 2.0;
  ParticleRow row(10, rho);
  std::vector<AttractivePoint> points;
  for (int i = 0; i < 10; ++i)
    points.push_back({row.x.col(i) + Eigen::Vector3d(0, 0, rho + 1), 1.0});
  FitOptions fo;
  fo.record_every = 5;
  fo.max_steps = 40;
  fo.residual_mean_tolerance_mm = 0.5;
  fo.residual_max_tolerance_mm = 0.5;
  fo.kinetic_tolerance = -1;
  int calls = 0;
  particles::State state(row.x);
  const FitResult r = row.fit(state, points, fo, [&calls](particles::State& s) {
    ++calls;
    s.x.row(2).array() += 0.3;
  });
  EXPECT_FALSE(r.converged);
  EXPECT_EQ(r.stop_reason, "step budget");
  EXPECT_EQ(r.explained_at_step, 10);
  EXPECT_EQ(calls, 2);
  ASSERT_EQ(r.history.size(), 9u);  // steps 0, 5, ..., 40
  EXPECT_NEAR(r.history[1].residual_mean_mm, 0.7, 1e-12);
  EXPECT_NEAR(r.history.back().residual_mean_mm, 0.4, 1e-12);
}

TEST(RunFit, OnceThePointsAreExplainedStopsAtTheStepTheBodyComesToRest) {
  // Particles with no force on them, each with a point on its surface, all moving at 1
  // mm/s along x and damped: each step multiplies v by c = exp(-K dt / m) = exp(-0.1), so
  // the kinetic energy per particle is 0.5 exp(-0.2 s) after s steps, at most 1e-4 from
  // step 43 (ln(5000) / 0.2 = 42.6). The points are explained at the row of step 20 (never
  // at the first), with the body still moving; the rows still come every 20 steps, and the
  // fit stops at step 43, not at step 60. They move 0.01 mm in all, across the points'
  // normals.
  const double rho = 2.0;
  ParticleRow row(10, rho);
  row.io.damping = 100;  // K (mass unit / s); m = 1, dt = 1e-3 s
  std::vector<AttractivePoint> points;
  for (int i = 0; i < 10; ++i)
    points.push_back({row.x.col(i) + Eigen::Vector3d(0, 0, rho), 1.0});
  FitOptions fo;
  fo.record_every = 20;
  fo.max_steps = 200;
  fo.kinetic_tolerance = 1e-4;
  particles::State state(row.x);
  state.v.row(0).setOnes();
  const FitResult r = row.fit(state, points, fo);
  EXPECT_TRUE(r.converged) << r.stop_reason;
  EXPECT_EQ(r.explained_at_step, 20);
  EXPECT_EQ(r.steps, 43);
  ASSERT_EQ(r.history.size(), 4u);  // steps 0, 20, 40 (rows as before), 43
  EXPECT_EQ(r.history[2].step, 40);
  EXPECT_EQ(r.history[3].step, 43);
  EXPECT_LE(r.history[3].kinetic_energy_per_particle, 1e-4);
  EXPECT_GT(r.history[2].kinetic_energy_per_particle, 1e-4);
}

}  // namespace
}  // namespace organfit::fitting
