#include "organfit/geometry/signed_distance.h"

#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <random>

#include "organfit/geometry/mask_ops.h"

namespace organfit::geometry {
namespace {

/// A ball of radius 10 mm about the origin on a 0.5 mm grid, rotated 30 degrees about z
/// (the field must follow the grid's direction).
LabelVolume rotated_ball() {
  ImageGeometry g =
      grid_covering({Eigen::Vector3d::Constant(-13), Eigen::Vector3d::Constant(13)}, 0.5, 0.0);
  g.direction = Eigen::AngleAxisd(M_PI / 6, Eigen::Vector3d::UnitZ()).toRotationMatrix();
  g.origin_mm = -(g.direction * g.spacing_mm.cwiseProduct(
                                    Eigen::Vector3d(g.size[0] - 1, g.size[1] - 1, g.size[2] - 1))) /
                2;
  LabelVolume ball(g);
  for (int k = 0; k < g.size[2]; ++k)
    for (int j = 0; j < g.size[1]; ++j)
      for (int i = 0; i < g.size[0]; ++i)
        ball.at(i, j, k) = g.index_to_physical(Eigen::Vector3d(i, j, k)).norm() <= 10.0;
  return ball;
}

// The sparse evaluation is the transforms' value at every point: two blobs and a cavity
// on a rotated grid of unequal spacings (rounding in every sum), points inside, outside,
// on the boundary and beyond the grid; and infinite for a mask without boundary.
TEST(SignedDistance, AtPointsIsTheWholeGridsValue) {
  ImageGeometry g;
  g.size = {41, 37, 23};
  g.spacing_mm = Eigen::Vector3d(0.977, 0.61, 2.5);
  g.direction = Eigen::AngleAxisd(0.4, Eigen::Vector3d(1, 2, 3).normalized()).toRotationMatrix();
  g.origin_mm = Eigen::Vector3d(-20.3, 7.1, -30.9);
  LabelVolume mask(g);
  for (int k = 0; k < g.size[2]; ++k)
    for (int j = 0; j < g.size[1]; ++j)
      for (int i = 0; i < g.size[0]; ++i) {
        const Eigen::Vector3d p(i * 0.977, j * 0.61, k * 2.5);
        const bool a = (p - Eigen::Vector3d(14, 10, 25)).norm() < 9 &&
                       (p - Eigen::Vector3d(14, 10, 25)).norm() > 3;  // with a cavity
        const bool b = (p - Eigen::Vector3d(30, 15, 30)).cwiseAbs().maxCoeff() < 5;
        mask.at(i, j, k) = a || b;
      }
  const SignedDistance whole(mask, false);
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> u(-0.1, 1.1);  // a tenth of the grid beyond it
  Eigen::Matrix3Xd points(3, 600);
  for (Eigen::Index c = 0; c < points.cols(); ++c) {
    const Eigen::Vector3d f(u(rng) * (g.size[0] - 1), u(rng) * (g.size[1] - 1),
                            u(rng) * (g.size[2] - 1));
    points.col(c) = g.index_to_physical(c % 3 == 0 ? f.array().round().matrix() : f);
  }
  const std::vector<double> sparse = signed_distance_at(mask, points);
  ASSERT_EQ(sparse.size(), 600u);
  int inside = 0;
  for (Eigen::Index c = 0; c < points.cols(); ++c) {
    EXPECT_EQ(sparse[static_cast<size_t>(c)], whole.at(points.col(c))) << c;
    inside += sparse[static_cast<size_t>(c)] < 0;
  }
  EXPECT_GT(inside, 10);  // both sides were tried
  const LabelVolume empty(g);
  EXPECT_TRUE(std::isinf(signed_distance_at(empty, points.leftCols(3))[1]));
}

// The smoothed distance is the binomial 1-4-6-4-1 along x, then y, then z, ends clamped,
// of the unsmoothed one (within slices: along x and y alone, less a level), value for value: each
// pass written out here as its definition, voxel by voxel from a whole grid into another, on a grid
// of unequal sizes (rows shorter than the filter included) and both ways of making it (smoothed()
// and the constructor).
TEST(SignedDistance, SmoothedIsTheBinomialOfEachAxisInTurn) {
  ImageGeometry g;
  g.size = {14, 3, 9};
  g.spacing_mm = {0.6, 0.9, 1.4};
  LabelVolume mask(g);
  std::mt19937 rng(7);
  for (auto& v : mask.labels)
    v = (rng() % 3) == 0;
  const SignedDistance raw(mask, false);
  std::vector<double> a(g.voxel_count()), b(g.voxel_count());
  for (int k = 0; k < g.size[2]; ++k)
    for (int j = 0; j < g.size[1]; ++j)
      for (int i = 0; i < g.size[0]; ++i)
        a[g.linear_index(i, j, k)] = raw.at_voxel(i, j, k);
  const double w[5] = {1 / 16.0, 4 / 16.0, 6 / 16.0, 4 / 16.0, 1 / 16.0};
  std::vector<double> within_slices;  // after the x and y passes
  for (int axis = 0; axis < 3; ++axis) {
    if (axis == 2) within_slices = a;
    for (int k = 0; k < g.size[2]; ++k)
      for (int j = 0; j < g.size[1]; ++j)
        for (int i = 0; i < g.size[0]; ++i) {
          double sum = 0;
          for (int o = -2; o <= 2; ++o) {
            int at[3] = {i, j, k};
            at[axis] = std::clamp(at[axis] + o, 0, g.size[axis] - 1);
            sum += w[o + 2] * a[g.linear_index(at[0], at[1], at[2])];
          }
          b[g.linear_index(i, j, k)] = sum;
        }
    a.swap(b);
  }
  // Within slices, less a level: the x and y passes alone, then the level subtracted.
  const double level = 0.037;
  const SignedDistance in_slices = raw.smoothed_within_slices(level);
  for (int k = 0; k < g.size[2]; ++k)
    for (int j = 0; j < g.size[1]; ++j)
      for (int i = 0; i < g.size[0]; ++i)
        ASSERT_EQ(in_slices.at_voxel(i, j, k), within_slices[g.linear_index(i, j, k)] - level);
  const SignedDistance smoothed = raw.smoothed(), made(mask, true);
  for (int k = 0; k < g.size[2]; ++k)
    for (int j = 0; j < g.size[1]; ++j)
      for (int i = 0; i < g.size[0]; ++i) {
        ASSERT_EQ(smoothed.at_voxel(i, j, k), a[g.linear_index(i, j, k)])
            << i << " " << j << " " << k;
        ASSERT_EQ(made.at_voxel(i, j, k), a[g.linear_index(i, j, k)]);
      }
}

TEST(SignedDistance, IsTheDistanceToABallsSurfaceWithinTheVoxelsStaircase) {
  const SignedDistance d(rotated_ball());
  for (const Eigen::Vector3d& dir : {Eigen::Vector3d(1, 0, 0), Eigen::Vector3d(0.3, -0.7, 0.648),
                                     Eigen::Vector3d(-0.5, -0.5, -0.7071)}) {
    const Eigen::Vector3d u = dir.normalized();
    for (double radius : {2.0, 4.0, 9.0, 9.8, 10.0, 10.3, 11.5, 12.5}) {
      Eigen::Vector3d gradient;
      // Half a voxel of staircase, and the smoothing rounds the ball's centre.
      EXPECT_NEAR(d.at(radius * u, &gradient), radius - 10.0, radius < 8 ? 0.4 : 0.3) << radius;
      if (radius >= 4) {
        EXPECT_GT(gradient.normalized().dot(u), 0.98) << radius;
      }
    }
  }
}

// Any nonzero label is inside: a mask of label 2 has label 1's distance, voxel for voxel.
TEST(SignedDistance, TakesAnyNonzeroLabelAsInside) {
  const LabelVolume ones = rotated_ball();
  LabelVolume twos = ones;
  for (auto& v : twos.labels)
    v = static_cast<std::uint8_t>(2 * v);
  const SignedDistance a(ones, false), b(twos, false);
  const ImageGeometry& g = ones.geometry;
  long long inside = 0;
  for (int k = 0; k < g.size[2]; ++k)
    for (int j = 0; j < g.size[1]; ++j)
      for (int i = 0; i < g.size[0]; ++i) {
        ASSERT_EQ(a.at_voxel(i, j, k), b.at_voxel(i, j, k)) << i << " " << j << " " << k;
        inside += a.at_voxel(i, j, k) < 0;
      }
  EXPECT_EQ(inside, ones.count(1));
}

TEST(SignedDistance, GradientIsTheInterpolantsDerivative) {
  const SignedDistance d(rotated_ball());
  const Eigen::Vector3d p(3.1, -6.27, 4.43);  // inside a cell, off its faces
  Eigen::Vector3d gradient;
  d.at(p, &gradient);
  const double h = 1e-6;
  for (int c = 0; c < 3; ++c) {
    const Eigen::Vector3d e = h * Eigen::Vector3d::Unit(c);
    EXPECT_NEAR(gradient(c), (d.at(p + e) - d.at(p - e)) / (2 * h), 1e-6);
  }
}

TEST(SignedDistance, BeyondTheGridAddsTheDistanceToIt) {
  const LabelVolume ball = rotated_ball();
  const SignedDistance d(ball);
  const Eigen::Vector3d axis = ball.geometry.direction.col(0);  // along the grid's i
  const Eigen::Vector3d edge =
      ball.geometry.index_to_physical(Eigen::Vector3d(ball.geometry.size[0] - 1, 25, 25));
  Eigen::Vector3d gradient;
  EXPECT_NEAR(d.at(edge + 7.0 * axis, &gradient), d.at(edge) + 7.0, 1e-9);
  EXPECT_NEAR(gradient.dot(axis), 1.0, 1e-9);
  EXPECT_GT(d.at(edge), 2.0);  // the ball is well inside the grid
}

// gradient_bound: no two points of a ball differ by more than the bound times their
// distance, within the grid and reaching beyond it; and the bound is no looser than it
// must be (an unsmoothed distance's slope is about 1, the bound at most sqrt(3)).
TEST(SignedDistance, GradientBoundHoldsBetweenAnyTwoPointsOfTheBall) {
  const LabelVolume ball = rotated_ball();
  for (const bool smooth : {false, true}) {
    const SignedDistance d(ball, smooth);
    std::mt19937 rng(7);
    std::uniform_real_distribution<double> u(-1, 1);
    double largest_ratio = 0;
    for (const auto& [centre, radius] :
         {std::pair{Eigen::Vector3d(2, -3, 1), 4.0}, std::pair{Eigen::Vector3d(9, 0, 0), 1.5},
          std::pair{Eigen::Vector3d(12.5, 0, 3), 3.0}}) {
      const double bound = d.gradient_bound(centre, radius);
      ASSERT_TRUE(std::isfinite(bound));
      EXPECT_LE(bound, std::sqrt(3.0) * (centre.norm() + radius > 12.9 ? std::sqrt(2.0) : 1.0));
      for (int trial = 0; trial < 4000; ++trial) {
        const Eigen::Vector3d a = centre + radius * Eigen::Vector3d(u(rng), u(rng), u(rng)) / 2;
        // Far pairs, and near ones (0.01 mm apart) for the local slope.
        const Eigen::Vector3d step(u(rng), u(rng), u(rng));
        const Eigen::Vector3d b =
            trial % 2
                ? Eigen::Vector3d(a + 0.01 * step.normalized())
                : Eigen::Vector3d(centre + radius * Eigen::Vector3d(u(rng), u(rng), u(rng)) / 2);
        const double ratio = std::abs(d.at(a) - d.at(b)) / (a - b).norm();
        EXPECT_LE(ratio, bound * (1 + 1e-9)) << a.transpose() << " / " << b.transpose();
        largest_ratio = std::max(largest_ratio, ratio);
      }
    }
    EXPECT_GT(largest_ratio, 0.9);  // the distance's own slope was seen
  }
  // Without a boundary (an empty mask) nothing is bounded.
  LabelVolume empty(ball.geometry);
  EXPECT_FALSE(std::isfinite(SignedDistance(empty, false).gradient_bound({0, 0, 0}, 1.0)));
}

// The bound over a ball is the largest over the blocks about the cells it touches, not
// over the grid: a slab (|x| <= 8 mm) beside a cube (the cube's corners the steep places),
// on a 1 mm grid. Where the slab's distance is the nearest (it varies along x alone, by
// 1 mm a voxel) the bound is 1; the ball's bound holds between its points wherever it
// lies, the cube's corners within it or not.
TEST(SignedDistance, GradientBoundIsTheLargestWhereTheBallLies) {
  const ImageGeometry g =
      grid_covering({Eigen::Vector3d::Constant(-30), Eigen::Vector3d::Constant(30)}, 1.0, 0.0);
  LabelVolume mask(g);
  for (int k = 0; k < g.size[2]; ++k)
    for (int j = 0; j < g.size[1]; ++j)
      for (int i = 0; i < g.size[0]; ++i) {
        const Eigen::Vector3d p = g.index_to_physical(Eigen::Vector3d(i, j, k));
        const bool cube =
            p.x() >= 20 && p.x() <= 26 && std::abs(p.y()) <= 3 && std::abs(p.z()) <= 3;
        mask.at(i, j, k) = std::abs(p.x()) <= 8 || cube;
      }
  const SignedDistance d(mask, false);
  const double global = d.gradient_bound();
  EXPECT_NEAR(global, std::sqrt(3.0), 1e-9);  // at the cube's corners
  EXPECT_NEAR(d.gradient_bound(Eigen::Vector3d(-20, 20, 20), 3.0), 1.0, 1e-12);
  EXPECT_NEAR(d.gradient_bound(Eigen::Vector3d(-15, 0, 0), 5.0), 1.0, 1e-12);
  // A larger ball is bounded over larger blocks: this one's (32 voxels a side) reach the
  // cube, 20 mm from its edge.
  EXPECT_NEAR(d.gradient_bound(Eigen::Vector3d(0, -15, 10), 12.0), global, 1e-12);
  EXPECT_NEAR(d.gradient_bound(Eigen::Vector3d(23, 3, 3), 1.0), global, 1e-12);
  std::mt19937 rng(11);
  std::uniform_real_distribution<double> u(-1, 1);
  for (int ball = 0; ball < 200; ++ball) {
    const Eigen::Vector3d centre = 24.0 * Eigen::Vector3d(u(rng), u(rng), u(rng));
    const double radius = 0.5 + 2.5 * (1 + u(rng));
    const double bound = d.gradient_bound(centre, radius);
    ASSERT_LE(bound, global + 1e-12);
    for (int trial = 0; trial < 50; ++trial) {
      Eigen::Vector3d a, b;
      do
        a = radius * Eigen::Vector3d(u(rng), u(rng), u(rng));
      while (a.norm() > radius);
      do
        b = radius * Eigen::Vector3d(u(rng), u(rng), u(rng));
      while (b.norm() > radius);
      a += centre, b += centre;
      EXPECT_LE(std::abs(d.at(a) - d.at(b)), bound * (a - b).norm() * (1 + 1e-9) + 1e-12)
          << centre.transpose() << " r " << radius;
    }
  }
}

/// An ellipsoid of semi-axes kEggSemi (mm) on 1 x 1 x 3 mm voxels, its slices' planes 0.4 mm
/// off its centre: a thick-sliced organ whose slices are not symmetric about it.
const Eigen::Vector3d kEggSemi(20, 14, 11);
LabelVolume egg_on_thick_slices() {
  ImageGeometry g = grid_covering({-kEggSemi, kEggSemi}, 1.0, 4.0);
  g.spacing_mm.z() = 3.0;
  g.size[2] = (g.size[2] + 2) / 3;
  g.origin_mm.z() = -1.5 * (g.size[2] - 1) + 0.4;
  LabelVolume egg(g);
  for (int k = 0; k < g.size[2]; ++k)
    for (int j = 0; j < g.size[1]; ++j)
      for (int i = 0; i < g.size[0]; ++i)
        egg.at(i, j, k) =
            g.index_to_physical(Eigen::Vector3d(i, j, k)).cwiseQuotient(kEggSemi).squaredNorm() <=
            1;
  return egg;
}

// The volume level: the region {at() < level} has the voxels' volume, measured here by
// uniform random points (4M over the ellipsoid's box: 0.1% standard error), on 1 x 1 x 3
// mm voxels where the zero level rounds the staircase's edges off by about 2%; every voxel
// centre keeps its side; a box whose faces lie between voxel centres loses only its edges
// at the zero level, so its level is near 0; a mask without boundary has 0.
TEST(SignedDistance, VolumeLevelEnclosesTheVoxelsVolume) {
  const Eigen::Vector3d& semi = kEggSemi;
  const LabelVolume egg = egg_on_thick_slices();
  const ImageGeometry& g = egg.geometry;
  const SignedDistance d(egg, false);
  const double level = d.volume_level();
  EXPECT_GT(level, 0.0);
  EXPECT_LE(level, 0.5);  // within the gap: half the smallest spacing
  for (int k = 0; k < g.size[2]; ++k)
    for (int j = 0; j < g.size[1]; ++j)
      for (int i = 0; i < g.size[0]; ++i)
        ASSERT_EQ(d.at_voxel(i, j, k) < level, egg.at(i, j, k) == 1) << i << " " << j << " " << k;
  std::mt19937_64 rng(7);
  const Eigen::Vector3d lo = -semi - Eigen::Vector3d(1, 1, 3), hi = -lo;
  std::uniform_real_distribution<double> ux(lo.x(), hi.x()), uy(lo.y(), hi.y()), uz(lo.z(), hi.z());
  const long long n = 4'000'000;
  long long at_level = 0, at_zero = 0;
  for (long long t = 0; t < n; ++t) {
    const double v = d.at(Eigen::Vector3d(ux(rng), uy(rng), uz(rng)));
    at_level += v < level, at_zero += v < 0;
  }
  const double box = (hi - lo).prod(), voxels = egg.volume_mm3(1);
  EXPECT_NEAR(box * at_level / n / voxels, 1.0, 0.004);
  EXPECT_LT(box * at_zero / n / voxels, 0.985);

  // The level is the organ's, not the grid's: the egg on a grid grown by 2, 5 and 3 voxels
  // (low side) and 4, 1 and 2 (high side) has the same level to the bit (a saved model
  // keeps its organ cropped about it).
  ImageGeometry wide = g;
  const int grow_lo[3] = {2, 5, 3}, grow_hi[3] = {4, 1, 2};
  for (int a = 0; a < 3; ++a)
    wide.size[a] += grow_lo[a] + grow_hi[a];
  wide.origin_mm = g.index_to_physical(Eigen::Vector3d(-grow_lo[0], -grow_lo[1], -grow_lo[2]));
  LabelVolume wide_egg(wide);
  for (int k = 0; k < g.size[2]; ++k)
    for (int j = 0; j < g.size[1]; ++j)
      for (int i = 0; i < g.size[0]; ++i)
        wide_egg.at(i + grow_lo[0], j + grow_lo[1], k + grow_lo[2]) = egg.at(i, j, k);
  EXPECT_EQ(SignedDistance(wide_egg, false).volume_level(), level);

  ImageGeometry c =
      grid_covering({Eigen::Vector3d::Constant(-12), Eigen::Vector3d::Constant(12)}, 0.5, 0.0);
  LabelVolume cube(c);
  for (int k = 0; k < c.size[2]; ++k)
    for (int j = 0; j < c.size[1]; ++j)
      for (int i = 0; i < c.size[0]; ++i)
        cube.at(i, j, k) =
            (c.index_to_physical(Eigen::Vector3d(i, j, k)).array().abs() < 7.6).all();
  const double cube_level = SignedDistance(cube, false).volume_level();
  EXPECT_GT(cube_level, 0.0);
  EXPECT_LT(cube_level, 0.01);  // of a gap of 0.25 mm
  EXPECT_EQ(SignedDistance(LabelVolume(c), false).volume_level(), 0.0);
}

// The levels by slice phase: the organ {beyond_level < 0} has the voxels' volume in every
// quarter of the half slice, not only on average. The egg of the test above on 1 x 1 x 3
// mm voxels, its cross-sections at a phase t of a slice each side of every plane of voxel
// centres, summed (areas on a 0.2 mm lattice) over 8 phases in each quarter, against the
// voxels' volume (0.9991, 1.0011, 1.0006, 1.0002): with one level for all, near the planes
// it is generous and near the midplanes short (1.0133, 1.0061, 0.9949, 0.9913). (Not at a
// single phase: the egg's flat ends lie at midplanes, and its region's end faces a level's
// height above them, so a phase within 0.03 of 1/2 counts them on both sides.) Every voxel centre
// keeps its side; beyond_level's gradient is its difference quotient, and volume_level_slope bounds
// the level's.
TEST(SignedDistance, LevelsBySlicePhaseKeepTheVolumeAtEveryPhase) {
  const Eigen::Vector3d& semi = kEggSemi;
  const LabelVolume egg = egg_on_thick_slices();
  const ImageGeometry& g = egg.geometry;
  const SignedDistance d(egg, false);
  const SignedDistance::LevelsBySlicePhase c = d.volume_levels().by_slice_phase_mm;
  EXPECT_LT(c[0], c[3]);  // the corners cut between the slices, not at them
  for (int k = 0; k < g.size[2]; ++k)
    for (int j = 0; j < g.size[1]; ++j)
      for (int i = 0; i < g.size[0]; ++i) {
        const Eigen::Vector3d centre = g.index_to_physical(Eigen::Vector3d(i, j, k));
        ASSERT_EQ(d.beyond_level(centre) < 0, egg.at(i, j, k) == 1) << i << " " << j << " " << k;
      }
  const double voxels = egg.volume_mm3(1), step = 0.2;
  const double single = d.volume_level();
  for (int quarter = 0; quarter < 4; ++quarter) {
    double by_phase = 0, at_single = 0;  // mm3: areas times the slice's thickness
    constexpr int kPhases = 8;           // midpoints of eighths of the quarter
    for (int n = 0; n < kPhases; ++n) {
      const double t = (quarter + (n + 0.5) / kPhases) / 8;
      for (int k = 0; k < g.size[2]; ++k)
        for (const double side : {-1.0, 1.0}) {
          const double z = g.origin_mm.z() + (k + side * t) * g.spacing_mm.z();
          for (double y = -semi.y() - 1; y <= semi.y() + 1; y += step)
            for (double x = -semi.x() - 1; x <= semi.x() + 1; x += step) {
              const Eigen::Vector3d p(x, y, z);
              by_phase += d.beyond_level(p) < 0;
              at_single += d.at(p) < single;
            }
        }
    }
    const double scale = step * step * g.spacing_mm.z() / 2 / kPhases / voxels;
    EXPECT_NEAR(by_phase * scale, 1.0, 0.003) << quarter;
    // One level for all is generous near the planes and short near the midplanes.
    if (quarter == 0) {
      EXPECT_GT(at_single * scale, 1.008);  // 1.013
    }
    if (quarter == 3) {
      EXPECT_LT(at_single * scale, 0.994);  // 0.991
    }
  }
  std::mt19937_64 rng(3);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  const double slope = d.volume_level_slope(), h = 1e-6;
  EXPECT_GT(slope, 0.0);
  for (int n = 0; n < 200; ++n) {
    const Eigen::Vector3d p = semi.cwiseProduct(Eigen::Vector3d(u(rng), u(rng), u(rng)));
    Eigen::Vector3d gradient;
    const double v = d.beyond_level(p, &gradient);
    EXPECT_DOUBLE_EQ(v, d.at(p) - d.volume_level_at(p));
    for (int a = 0; a < 3; ++a) {
      const Eigen::Vector3d e = h * Eigen::Vector3d::Unit(a);
      EXPECT_NEAR((d.beyond_level(p + e) - d.beyond_level(p - e)) / (2 * h), gradient[a], 1e-5)
          << p.transpose();
    }
    const Eigen::Vector3d ez = 1e-3 * Eigen::Vector3d::UnitZ();
    EXPECT_LE(std::abs(d.volume_level_at(p + ez) - d.volume_level_at(p)), slope * 1e-3 + 1e-12);
    EXPECT_LE(d.volume_level_at(p), d.highest_volume_level());
  }
}

}  // namespace
}  // namespace organfit::geometry
