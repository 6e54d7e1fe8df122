#include "organfit/fitting/skin.h"

#include <gtest/gtest.h>

#include "organfit/particles/lattice_fill.h"

namespace organfit::fitting {
namespace {

/// A simple cubic lattice of n^3 touching balls (spacing 2 rho).
Eigen::Matrix3Xd cubic_lattice(int n, double rho) {
  Eigen::Matrix3Xd x(3, n * n * n);
  int c = 0;
  for (int k = 0; k < n; ++k)
    for (int j = 0; j < n; ++j)
      for (int i = 0; i < n; ++i)
        x.col(c++) = 2 * rho * Eigen::Vector3d(i, j, k) + Eigen::Vector3d(0.3, -0.2, 0.1);
  return x;
}

TEST(SkinDetector, CubicLatticeSkinIsExactlyItsOuterLayer) {
  for (int n : {3, 5, 8}) {
    const double rho = 1.5;
    const Eigen::Matrix3Xd x = cubic_lattice(n, rho);
    SkinDetector skin(rho, rho);
    skin.update(x);
    EXPECT_EQ(static_cast<int>(skin.skin().size()), n * n * n - (n - 2) * (n - 2) * (n - 2)) << n;
    for (int k = 0; k < n; ++k)
      for (int j = 0; j < n; ++j)
        for (int i = 0; i < n; ++i) {
          const bool outer = i == 0 || j == 0 || k == 0 || i == n - 1 || j == n - 1 || k == n - 1;
          EXPECT_EQ(skin.is_skin(i + n * (j + n * k)), outer) << i << "," << j << "," << k;
        }
  }
}

TEST(SkinDetector, FccEllipsoidSkinIsTheOuterShellAndTinyVoxelsMarkEverything) {
  particles::CohesionParams p;
  p.r0_mm = 3.7;
  const double rho = p.r0_mm / 2;
  const double a = particles::fcc_equilibrium_spacing(particles::LennardJones(p));
  const Eigen::Matrix3Xd x = particles::fill_ellipsoid({48, 38, 30}, {0, 0, 0}, a);
  SkinDetector skin(rho, rho);
  skin.update(x);
  // Every skin particle lies within 1.5 a of the ellipsoid surface (outer shell), and
  // every particle that close to its widest extent is skin.
  for (int i : skin.skin()) {
    const double q = x.col(i).cwiseQuotient(Eigen::Vector3d(24, 19, 15)).norm();
    EXPECT_GT(q, 1.0 - 1.6 * a / 15.0) << i;
  }
  EXPECT_LT(skin.skin().size(), x.cols() * 0.75);
  EXPECT_GT(skin.skin().size(), x.cols() * 0.35);
  SkinDetector fine(rho / 4, rho);  // METHOD s.8: rho/4 marks (nearly) all particles
  fine.update(x);
  EXPECT_GT(fine.skin().size(), 0.95 * x.cols());
}

TEST(SkinDetector, InsideTestAndRecomputationOnlyAfterMovement) {
  const double rho = 1.0;
  const Eigen::Matrix3Xd x = cubic_lattice(6, rho);  // spans [0.3, 10.3] etc.
  SkinDetector skin(rho, rho, 0.5);
  EXPECT_TRUE(skin.update(x));
  EXPECT_TRUE(skin.inside(Eigen::Vector3d(5, 5, 5)));
  EXPECT_TRUE(skin.inside(Eigen::Vector3d(0.3, 0, 0)));
  EXPECT_FALSE(skin.inside(Eigen::Vector3d(-3, 5, 5)));
  EXPECT_FALSE(skin.inside(Eigen::Vector3d(100, 5, 5)));
  Eigen::Matrix3Xd moved = x;
  moved(0, 3) += 0.4;  // < 0.5 h
  EXPECT_FALSE(skin.update(moved));
  moved(0, 3) += 0.2;
  EXPECT_TRUE(skin.update(moved));
  EXPECT_EQ(skin.computations(), 2);
}

TEST(SkinDetector, HollowShellHasInsideCavityNotReachableFromOutside) {
  // A closed spherical shell of balls: its cavity is inside the closed body.
  std::vector<Eigen::Vector3d> pts;
  for (int t = 0; t < 40; ++t)
    for (int u = 0; u < 80; ++u) {
      const double th = M_PI * (t + 0.5) / 40, ph = 2 * M_PI * u / 80;
      pts.push_back(10 * Eigen::Vector3d(std::sin(th) * std::cos(ph), std::sin(th) * std::sin(ph),
                                         std::cos(th)));
    }
  Eigen::Matrix3Xd x(3, pts.size());
  for (size_t i = 0; i < pts.size(); ++i)
    x.col(i) = pts[i];
  SkinDetector skin(0.5, 1.0);
  skin.update(x);
  EXPECT_TRUE(skin.inside(Eigen::Vector3d::Zero()));
}

TEST(SkinDetector, EmptyModelAndBadParameters) {
  SkinDetector skin(1.0, 1.0);
  skin.update(Eigen::Matrix3Xd(3, 0));
  EXPECT_TRUE(skin.skin().empty());
  EXPECT_FALSE(skin.inside(Eigen::Vector3d::Zero()));
  EXPECT_THROW(SkinDetector(0.0, 1.0), std::invalid_argument);
  EXPECT_THROW(SkinDetector(1.0, -1.0), std::invalid_argument);
  EXPECT_THROW(SkinDetector(1.0, 1.0, 0.0), std::invalid_argument);
}

}  // namespace
}  // namespace organfit::fitting
