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

TEST(SkinDetector, ClosedBodyIsEveryVoxelNotReachableFromTheBorder) {
  // Two shells of balls: one closed (its cavity inside), one with an opening at its pole
  // (its cavity reachable from outside). Against a breadth-first fill of the free voxels
  // from the border, on the detector's own grid and voxel rule.
  std::vector<Eigen::Vector3d> pts;
  for (int shell = 0; shell < 2; ++shell)
    for (int t = 0; t < 40; ++t)
      for (int u = 0; u < 80; ++u) {
        const double th = M_PI * (t + 0.5) / 40, ph = 2 * M_PI * u / 80;
        if (shell == 1 && th < 0.4) continue;  // the opening
        pts.push_back(Eigen::Vector3d(30 * shell, 0, 0) +
                      10 * Eigen::Vector3d(std::sin(th) * std::cos(ph), std::sin(th) * std::sin(ph),
                                           std::cos(th)));
      }
  Eigen::Matrix3Xd x(3, pts.size());
  for (size_t i = 0; i < pts.size(); ++i)
    x.col(i) = pts[i];
  const double rho = 1.0, h = 0.5;
  SkinDetector skin(h, rho);
  skin.update(x);
  const geometry::ImageGeometry& g = skin.grid();
  const int nx = g.size[0], ny = g.size[1], nz = g.size[2];
  // Kept: a voxel whose box lies within rho of a centre (each ball's bounding voxels).
  std::vector<std::uint8_t> kept(static_cast<size_t>(g.voxel_count()), 0);
  for (Eigen::Index p = 0; p < x.cols(); ++p) {
    const Eigen::Vector3d c = g.physical_to_index(x.col(p));
    for (int k = int(c.z()) - 4; k <= int(c.z()) + 4; ++k)
      for (int j = int(c.y()) - 4; j <= int(c.y()) + 4; ++j)
        for (int i = int(c.x()) - 4; i <= int(c.x()) + 4; ++i) {
          if (i < 0 || j < 0 || k < 0 || i >= nx || j >= ny || k >= nz) continue;
          const Eigen::Vector3d lo = g.index_to_physical(Eigen::Vector3d(i, j, k)).array() - h / 2;
          const Eigen::Vector3d gap =
              (lo - x.col(p)).cwiseMax(x.col(p) - (lo.array() + h).matrix()).cwiseMax(0.0);
          if (gap.squaredNorm() <= rho * rho)
            kept[static_cast<size_t>(g.linear_index(i, j, k))] = 1;
        }
  }
  std::vector<std::uint8_t> outside(kept.size(), 0);
  std::vector<Eigen::Vector3i> queue;
  auto visit = [&](int i, int j, int k) {
    if (i < 0 || j < 0 || k < 0 || i >= nx || j >= ny || k >= nz) return;
    const auto v = static_cast<size_t>(g.linear_index(i, j, k));
    if (kept[v] || outside[v]) return;
    outside[v] = 1;
    queue.emplace_back(i, j, k);
  };
  for (int k = 0; k < nz; ++k)
    for (int j = 0; j < ny; ++j)
      for (int i = 0; i < nx; ++i)
        if (i == 0 || j == 0 || k == 0 || i == nx - 1 || j == ny - 1 || k == nz - 1) visit(i, j, k);
  for (size_t q = 0; q < queue.size(); ++q) {
    const Eigen::Vector3i c = queue[q];
    for (int d = 0; d < 3; ++d)
      for (int s = -1; s <= 1; s += 2) {
        Eigen::Vector3i n = c;
        n[d] += s;
        visit(n.x(), n.y(), n.z());
      }
  }
  long long mismatches = 0, cavity = 0;
  for (int k = 0; k < nz; ++k)
    for (int j = 0; j < ny; ++j)
      for (int i = 0; i < nx; ++i) {
        const auto v = static_cast<size_t>(g.linear_index(i, j, k));
        mismatches += skin.inside(g.index_to_physical(Eigen::Vector3d(i, j, k))) == !!outside[v];
        cavity += !kept[v] && !outside[v];
      }
  EXPECT_EQ(mismatches, 0);
  EXPECT_GT(cavity, 1000);  // the closed shell's cavity, about 4/3 pi 8^3 / h^3 voxels
  EXPECT_TRUE(skin.inside(Eigen::Vector3d::Zero()));
  EXPECT_FALSE(skin.inside(Eigen::Vector3d(30, 0, 0)));
}

}  // namespace
}  // namespace organfit::fitting
