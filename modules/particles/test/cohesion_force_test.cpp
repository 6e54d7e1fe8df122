// CohesionForce over a neighbour list: equal to all pairs, F = -grad E, Newton's third law.
#include "organfit/particles/cohesion_force.h"

#include <gtest/gtest.h>
#include <omp.h>

#include "test_systems.h"

namespace organfit::particles {
namespace {

using testing::all_pairs_energy;
using testing::all_pairs_forces;
using testing::random_cloud;

class CohesionForceOnRandomSystems : public ::testing::TestWithParam<std::pair<int, int>> {
 protected:
  CohesionParams params() const {
    CohesionParams p;
    p.m = GetParam().first;
    p.n = GetParam().second;
    p.r0_mm = 2.0;
    return p;
  }
};

TEST_P(CohesionForceOnRandomSystems, EqualsAllPairsAndSumsToZero) {
  const CohesionParams p = params();
  const LennardJones law(p);
  for (unsigned seed : {1u, 2u, 3u}) {
    State s(random_cloud(300, 16.0, 0.6 * p.r0_mm, seed));
    CohesionForce term(law, 0.3 * p.r0_mm);
    Forces f = Forces::Zero(3, s.size());
    const double e = term.add_forces(s, f, true);
    const Forces ref = all_pairs_forces(law, s.x);
    EXPECT_LT((f - ref).cwiseAbs().maxCoeff(), 1e-9 * (1 + ref.cwiseAbs().maxCoeff()));
    EXPECT_NEAR(e, all_pairs_energy(law, s.x), 1e-9 * (1 + std::abs(e)));
    EXPECT_LT(f.rowwise().sum().norm(), 1e-9 * (1 + f.cwiseAbs().maxCoeff()));
    EXPECT_GT(term.neighbour_list().pair_count(), 0);
  }
}

TEST_P(CohesionForceOnRandomSystems, ForceIsMinusEnergyGradientByFiniteDifferences) {
  const CohesionParams p = params();
  const LennardJones law(p);
  State s(random_cloud(40, 7.0, 0.7 * p.r0_mm, 7));
  CohesionForce term(law, 0.3 * p.r0_mm);
  Forces f = Forces::Zero(3, s.size());
  term.add_forces(s, f, false);
  const double h = 1e-6;
  for (int i = 0; i < s.size(); i += 3) {
    for (int d = 0; d < 3; ++d) {
      State plus = s, minus = s;
      plus.x(d, i) += h;
      minus.x(d, i) -= h;
      const double grad =
          (all_pairs_energy(law, plus.x) - all_pairs_energy(law, minus.x)) / (2 * h);
      EXPECT_NEAR(f(d, i), -grad, 1e-5 * (1 + std::abs(grad))) << "particle " << i << " axis " << d;
    }
  }
}

INSTANTIATE_TEST_SUITE_P(Exponents, CohesionForceOnRandomSystems,
                         ::testing::Values(std::make_pair(6, 12), std::make_pair(4, 8),
                                           std::make_pair(12, 24), std::make_pair(5, 9)));

TEST(CohesionForce, EqualsAllPairsInACompressedClusterWithLongNeighbourLists) {
  // 200 particles in a 3 mm cube at r0 = 2 mm: every pair is listed (lists longer than
  // the pair loop's chunk) and many lie below the floor (the linearised law).
  CohesionParams p;
  p.r0_mm = 2.0;
  const LennardJones law(p);
  State s(random_cloud(200, 3.0, 0.0, 11));
  CohesionForce term(law, 0.6);
  Forces f = Forces::Zero(3, s.size());
  const double e = term.add_forces(s, f, true);
  EXPECT_EQ(term.neighbour_list().pair_count(), 200 * 199 / 2);
  const Forces ref = all_pairs_forces(law, s.x);
  EXPECT_TRUE(f.allFinite());
  EXPECT_LT((f - ref).cwiseAbs().maxCoeff(), 1e-9 * (1 + ref.cwiseAbs().maxCoeff()));
  EXPECT_NEAR(e, all_pairs_energy(law, s.x), 1e-9 * (1 + std::abs(e)));
}

TEST(CohesionForce, NeighbourListRebuildsOnlyAfterHalfSkinDisplacement) {
  CohesionParams p;
  const LennardJones law(p);
  State s(random_cloud(200, 10.0, 0.8, 11));
  CohesionForce term(law, 0.4);
  Forces f = Forces::Zero(3, s.size());
  term.add_forces(s, f, false);
  EXPECT_EQ(term.neighbour_list().builds(), 1);
  s.x(0, 5) += 0.19;  // < skin/2
  term.add_forces(s, f, false);
  EXPECT_EQ(term.neighbour_list().builds(), 1);
  s.x(0, 5) += 0.02;  // total 0.21 > skin/2
  f.setZero();
  term.add_forces(s, f, false);
  EXPECT_EQ(term.neighbour_list().builds(), 2);
  const Forces ref = all_pairs_forces(law, s.x);
  EXPECT_LT((f - ref).cwiseAbs().maxCoeff(), 1e-9 * (1 + ref.cwiseAbs().maxCoeff()));
}

TEST(CohesionForce, PairwiseDampingConservesMomentumAndOpposesRelativeMotion) {
  CohesionParams p;
  const LennardJones law(p);
  State s(random_cloud(100, 6.0, 0.8, 5));
  s.v = Eigen::Matrix3Xd::Random(3, s.size());
  CohesionForce damped(law, 0.3, 2.0), plain(law, 0.3);
  Forces fd = Forces::Zero(3, s.size()), fp = Forces::Zero(3, s.size());
  damped.add_forces(s, fd, false);
  plain.add_forces(s, fp, false);
  const Forces fdamp = fd - fp;
  EXPECT_LT(fdamp.rowwise().sum().norm(), 1e-10);
  EXPECT_LT((fdamp.array() * s.v.array()).sum(), 0.0);  // dissipates: power < 0
}

TEST(CohesionForce, EmptyOneParticleAndIsolatedParticleHaveNoForce) {
  const LennardJones law(CohesionParams{});
  CohesionForce term(law, 0.3);
  State empty(Positions(3, 0));
  Forces f0(3, 0);
  EXPECT_EQ(term.add_forces(empty, f0, true), 0.0);
  State one(Positions::Zero(3, 1));
  Forces f1 = Forces::Zero(3, 1);
  EXPECT_EQ(term.add_forces(one, f1, true), 0.0);
  EXPECT_EQ(f1.norm(), 0.0);
  Positions x(3, 3);
  x << 0, 1, 1000, 0, 0, 0, 0, 0, 0;  // a pair and a particle far outside the cutoff
  State s(x);
  Forces f = Forces::Zero(3, 3);
  term.add_forces(s, f, false);
  EXPECT_EQ(f.col(2).norm(), 0.0);
  EXPECT_NEAR(f.col(0).norm(), 0.0, 1e-12);  // the pair sits at r0
}

TEST(CohesionForce, CoincidentAndNearlyCoincidentPairsGiveLargeFiniteOpposedForces) {
  CohesionParams p;
  p.m = 20;
  p.n = 40;
  const LennardJones law(p);
  for (double gap : {0.0, 0.01}) {
    Positions x(3, 2);
    x << 0, gap, 0, 0, 0, 0;
    State s(x);
    CohesionForce term(law, 0.3);
    Forces f = Forces::Zero(3, 2);
    term.add_forces(s, f, true);
    EXPECT_TRUE(f.allFinite());
    EXPECT_GT(f.col(0).norm(), law.force(law.floor_distance()));
    EXPECT_LT((f.col(0) + f.col(1)).norm(), 1e-9 * f.col(0).norm());
  }
}

TEST(CohesionForce, IdenticalResultsWithOneAndTwoThreads) {
  CohesionParams p;
  const LennardJones law(p);
  State s(random_cloud(6000, 38.0, 0.7, 3));
  ASSERT_GT(s.size(), kParallelMinParticles);
  Forces f1 = Forces::Zero(3, s.size()), f2 = Forces::Zero(3, s.size());
  const int saved = omp_get_max_threads();
  omp_set_num_threads(1);
  CohesionForce a(law, 0.3);
  const double e1 = a.add_forces(s, f1, true);
  omp_set_num_threads(2);
  CohesionForce b(law, 0.3);
  const double e2 = b.add_forces(s, f2, true);
  omp_set_num_threads(saved);
  EXPECT_EQ((f1 - f2).cwiseAbs().maxCoeff(), 0.0);  // bit-identical
  EXPECT_EQ(e1, e2);
}

}  // namespace
}  // namespace organfit::particles
