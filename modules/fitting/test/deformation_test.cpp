// Deformation: phi^-1(q) = M^-1(q + u(q)) defined everywhere. At rest it is the global
// map exactly; an affine motion of the particles is carried exactly, also across a
// region the particles left (the harmonic part reproduces affine fields); far away it is
// the global map; a folding motion is seen; push_forward inverts pull_back.
#include "organfit/fitting/deformation.h"

#include <gtest/gtest.h>

#include <Eigen/LU>
#include <cmath>
#include <random>

#include "../src/central_differences.h"

namespace organfit::fitting {
namespace {

constexpr double kSpacing = 3.0;  // particle spacing (mm)

/// Particles on a cubic lattice inside an ellipsoid of semi-axes 20, 14, 11 mm, less a
/// ball of `hole_mm` at the centre (a tear).
particles::Positions ellipsoid(double hole_mm = 0) {
  std::vector<Eigen::Vector3d> pts;
  for (double z = -11; z <= 11; z += kSpacing)
    for (double y = -14; y <= 14; y += kSpacing)
      for (double x = -20; x <= 20; x += kSpacing) {
        const Eigen::Vector3d p(x, y, z);
        if (p.cwiseQuotient(Eigen::Vector3d(20, 14, 11)).norm() <= 0.9 && p.norm() >= hole_mm)
          pts.push_back(p);
      }
  particles::Positions x(3, static_cast<Eigen::Index>(pts.size()));
  for (size_t i = 0; i < pts.size(); ++i)
    x.col(static_cast<Eigen::Index>(i)) = pts[i];
  return x;
}

GlobalMap bend() {
  GlobalMap map;
  map.affine.a =
      Eigen::Vector3d(1.2, 1 / std::sqrt(1.2), 1 / std::sqrt(1.2)).asDiagonal();  // det 1
  map.affine.t = Eigen::Vector3d(2, -1, 0.5);
  map.shears.c(3) = 0.004;  // y += 0.004 u_x^2
  return map;
}

TEST(Deformation, AtRestIsTheGlobalMapExactly) {
  const particles::Positions x = ellipsoid();
  const GlobalMap map = bend();
  particles::Positions placed(3, x.cols());
  for (Eigen::Index i = 0; i < x.cols(); ++i)
    placed.col(i) = map.apply(x.col(i));
  const Deformation phi(map, placed, placed, 2 * kSpacing);
  for (const Eigen::Vector3d& r :
       {Eigen::Vector3d(0, 0, 0), Eigen::Vector3d(19, 2, -3), Eigen::Vector3d(300, -200, 50)}) {
    EXPECT_LT((phi.pull_back(map.apply(r)) - r).norm(), 1e-9) << r.transpose();
    EXPECT_LT((phi.push_forward(r) - map.apply(r)).norm(), 1e-8) << r.transpose();
    EXPECT_NEAR(phi.volume_ratio(map.apply(r)), 1.0, 1e-12);
  }
  EXPECT_EQ(phi.fitted_nodes() + phi.harmonic_nodes(), 0);  // no lattice at rest
  EXPECT_FALSE(phi.folds());
  // The global map keeps volume: det of pull_back's gradient (central differences) is 1.
  const Eigen::Vector3d q = map.apply(Eigen::Vector3d(12, -5, 4));
  const Eigen::Matrix3d g =
      detail::central_jacobian([&](const Eigen::Vector3d& p) { return phi.pull_back(p); }, q, 1e-3);
  EXPECT_NEAR(g.determinant(), 1.0, 1e-6);
}

TEST(Deformation, IsTheIdentityOnlyAtRestUnderNoMap) {
  const particles::Positions x = ellipsoid();
  EXPECT_TRUE(Deformation().identity());
  GlobalMap none;  // the identity, its shears' centre set (as a fit sets it)
  none.shears.centre = Eigen::Vector3d(12.3, -45.6, 78.9);
  const Deformation rest(none, x, x, 2 * kSpacing);
  EXPECT_TRUE(rest.identity());
  // The identity gives every point back exactly (the planning organ voxel for voxel).
  for (const Eigen::Vector3d& q :
       {Eigen::Vector3d(0.1, -7.3, 2.9), Eigen::Vector3d(-123.456, 1e-3, 98.7)}) {
    EXPECT_EQ(rest.pull_back(q), q);
    EXPECT_EQ(rest.volume_ratio(q), 1.0);
  }
  EXPECT_FALSE(Deformation(bend(), x, x, 2 * kSpacing).identity());  // at rest, a map
  GlobalMap shift;
  shift.affine.t.x() = 1e-9;
  EXPECT_FALSE(Deformation(shift, x, x, 2 * kSpacing).identity());
  GlobalMap shear;
  shear.shears.c(14) = 1e-9;
  EXPECT_FALSE(Deformation(shear, x, x, 2 * kSpacing).identity());
  particles::Positions moved = x;
  moved(1, 7) += 0.01;  // one particle moved: a local displacement
  EXPECT_FALSE(Deformation(GlobalMap{}, x, moved, 2 * kSpacing).identity());
}

TEST(Deformation, CarriesAnAffineMotionAcrossATearExactly) {
  // A hole of 6 mm radius at the centre, no particle in it: u there is harmonic, and an
  // affine field is harmonic, so the hole is carried as the rest.
  const particles::Positions x0 = ellipsoid(6.0);
  Eigen::Matrix3d a;
  a << 1.1, 0.05, 0.0, -0.03, 0.95, 0.04, 0.02, 0.0, 0.97;
  const Eigen::Vector3d t(1.5, -1, 0.5);
  const particles::Positions x1 = (a * x0).colwise() + t;
  const Deformation phi(GlobalMap{}, x0, x1, 2 * kSpacing);
  EXPECT_GT(phi.harmonic_nodes(), 0);
  for (const Eigen::Vector3d& r : {Eigen::Vector3d(0, 0, 0), Eigen::Vector3d(2, -2, 1),
                                   Eigen::Vector3d(10, 5, -4), Eigen::Vector3d(17.5, 0, 0)}) {
    const Eigen::Vector3d q = a * r + t;
    EXPECT_LT((phi.pull_back(q) - r).norm(), 1e-4) << r.transpose();
    EXPECT_LT((phi.push_forward(r) - q).norm(), 1e-4) << r.transpose();
    EXPECT_NEAR(phi.volume_ratio(q), a.determinant(), 1e-4) << r.transpose();
  }
  EXPECT_FALSE(phi.folds());
}

TEST(Deformation, FallsToTheGlobalMapFarAwayWithoutFolding) {
  // Every particle moved 5 mm along x: u = -5 mm near them, 0 beyond the lattice.
  const particles::Positions x0 = ellipsoid();
  const particles::Positions x1 = x0.colwise() + Eigen::Vector3d(5, 0, 0);
  const Deformation phi(GlobalMap{}, x0, x1, 2 * kSpacing);
  EXPECT_LT((phi.pull_back(Eigen::Vector3d(5, 0, 0)) - Eigen::Vector3d(0, 0, 0)).norm(), 1e-5);
  EXPECT_EQ(phi.pull_back(Eigen::Vector3d(200, 0, 0)), Eigen::Vector3d(200, 0, 0));  // M = id
  // Between, continuous and invertible: the tissue ahead of the body is compressed and
  // the tissue behind it stretched, within det(grad phi) in [1/4, 4] (measured: 0.62 to
  // 3.35 for this 5 mm shift with a 6 mm support).
  EXPECT_FALSE(phi.folds());
  EXPECT_GT(phi.min_volume_ratio(), 0.25);
  EXPECT_LT(phi.max_volume_ratio(), 4.0);
  const geometry::Aabb box = phi.local_box();
  // u's gradient: about nothing within the body (u the same everywhere there), steep where
  // it falls beyond it; a box's bound is where the box lies.
  const double falling = phi.u_gradient_bound(box);
  EXPECT_GT(falling, 0.2);
  EXPECT_LT(phi.u_gradient_bound({Eigen::Vector3d(3, -2, -2), Eigen::Vector3d(7, 2, 2)}), 1e-3);
  double previous = phi.pull_back(Eigen::Vector3d(25, 0, 0)).x();
  for (double x = 25.25; x <= box.max_mm.x() + 2; x += 0.25) {
    const double now = phi.pull_back(Eigen::Vector3d(x, 0, 0)).x();
    EXPECT_GT(now, previous) << x;  // monotone along x: no fold
    EXPECT_LT(now - previous, 0.25 * 4.0) << x;
    previous = now;
  }
}

TEST(Deformation, HoldsUAtZeroBeyondDOfItsAnswersInsideAConcaveBody) {
  // A U of particles (arms at 30 <= |y| <= 45 mm, joined at x <= -15 mm) moved 5 mm along
  // x: D = max(2h, 2 * 5 mm) = 12 mm. Inside the U, 30 mm from every particle and over
  // 20 mm from every node their moving least squares answer, u is zero (phi the global
  // map, here the identity), though the lattice's box covers the gap; within D of an
  // arm it is the harmonic part's, falling from the arm's move.
  std::vector<Eigen::Vector3d> pts;
  for (double z = -6; z <= 6; z += kSpacing)
    for (double y = -45; y <= 45; y += kSpacing)
      for (double x = -30; x <= 30; x += kSpacing)
        if (x <= -15 || std::abs(y) >= 30) pts.emplace_back(x, y, z);
  particles::Positions x0(3, static_cast<Eigen::Index>(pts.size()));
  for (size_t i = 0; i < pts.size(); ++i)
    x0.col(static_cast<Eigen::Index>(i)) = pts[i];
  const particles::Positions x1 = x0.colwise() + Eigen::Vector3d(5, 0, 0);
  const Deformation phi(GlobalMap{}, x0, x1, 2 * kSpacing);
  const Eigen::Vector3d centre(25, 0, 0);  // 30 mm from the arms' and the base's particles
  const geometry::Aabb box = phi.local_box();
  EXPECT_TRUE((centre.array() > box.min_mm.array()).all() &&
              (centre.array() < box.max_mm.array()).all());
  EXPECT_LT((phi.pull_back(centre) - centre).norm(), 1e-12);
  const Eigen::Vector3d near_arm(20, 21, 0);  // 9 mm from the moved arm's inner face (y = 30)
  const double u = (phi.pull_back(near_arm) - near_arm).norm();
  EXPECT_GT(u, 0.1);
  EXPECT_LT(u, 5.0);  // no interior extremum: within the particles' moves
  EXPECT_FALSE(phi.folds());
}

TEST(Deformation, ExtrapolatesNoFoldFromTheParticlesJitter) {
  // No change of shape, the particles jittered about their places (sd 0.2 of their
  // spacing on each axis). Past the outermost particles the field is extrapolated from
  // neighbours spread thinly across the surface, which amplifies their jitter into folds
  // beyond the surface unless each answer is at least as certain as one particle's
  // displacement.
  const particles::Positions x0 = ellipsoid();
  std::mt19937 rng(7);
  std::normal_distribution<double> jitter(0.0, 0.2 * kSpacing);
  particles::Positions x1 = x0;
  for (Eigen::Index i = 0; i < x1.cols(); ++i)
    for (int a = 0; a < 3; ++a)
      x1(a, i) += jitter(rng);
  const Deformation phi(GlobalMap{}, x0, x1, 2 * kSpacing);
  EXPECT_FALSE(phi.folds());
  EXPECT_GT(phi.min_volume_ratio(), 0.25);
}

TEST(Deformation, SeesAFoldingMotion) {
  // The particles mirrored in x: det(grad phi) = -1.
  const particles::Positions x0 = ellipsoid();
  particles::Positions x1 = x0;
  x1.row(0) *= -1;
  const Deformation phi(GlobalMap{}, x0, x1, 2 * kSpacing);
  EXPECT_TRUE(phi.folds());
}

TEST(Deformation, RefusesBadInput) {
  const particles::Positions x = ellipsoid();
  EXPECT_THROW(Deformation(GlobalMap{}, x, x.leftCols(3), 5.0), std::invalid_argument);
  EXPECT_THROW(Deformation(GlobalMap{}, x, x, 0.0), std::invalid_argument);
  particles::Positions flung = x;
  flung(1, 0) = 3000;
  EXPECT_THROW(Deformation(GlobalMap{}, x, flung, 5.0), std::invalid_argument);
  const Deformation identity;
  EXPECT_EQ(identity.pull_back(Eigen::Vector3d(1, 2, 3)), Eigen::Vector3d(1, 2, 3));
}

}  // namespace
}  // namespace organfit::fitting
