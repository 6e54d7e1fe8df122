#include "organfit/geometry/shape.h"

#include <gtest/gtest.h>

#include <cmath>
#include <memory>
#include <random>

namespace organfit::geometry {
namespace {

TEST(Shapes, LungHasItsNotchAndUnknownShapesAreRefused) {
  const Shape lung = make_shape("lung", {40, 30, 60}, {0, 0, 0});
  EXPECT_TRUE(lung.inside({10, 0, 0}));
  EXPECT_FALSE(lung.inside({-18, 0, -6}));
  EXPECT_LT(shape_volume_mm3(lung, 1.0),
            shape_volume_mm3(make_shape("ellipsoid", {40, 30, 60}, {0, 0, 0}), 1.0));
  EXPECT_THROW(make_shape("donut", {1, 1, 1}, {0, 0, 0}), std::invalid_argument);
}

// A horseshoe (a ring of radii 8 and 16 mm with a quarter cut away, 6 slices of 2 mm): its
// centroid lies in the hole. Rays start from its deepest voxel, the centre of its largest
// inscribed ball, found here by brute force over every pair of voxels; from the centroid
// of a mask that holds it.
TEST(Shapes, RaysStartFromAMasksDeepestVoxelNotItsCentroid) {
  ImageGeometry g;
  g.size = {40, 40, 8};
  g.spacing_mm = {1, 1, 2};
  g.origin_mm = {-19.5, -19.5, -7};
  auto mask = std::make_shared<LabelVolume>(g);
  for (int k = 1; k <= 6; ++k)
    for (int j = 0; j < g.size[1]; ++j)
      for (int i = 0; i < g.size[0]; ++i) {
        const Eigen::Vector3d p = g.index_to_physical(Eigen::Vector3d(i, j, k));
        const double r = std::hypot(p.x(), p.y());
        if (r >= 8 && r <= 16 && !(p.x() > 0 && p.y() > 0)) mask->at(i, j, k) = 1;
      }
  const Shape s = make_mask_shape(mask);
  ASSERT_FALSE(s.inside(s.centre_mm));  // the centroid: in the hole
  const Eigen::Vector3d origin = ray_origin_mm(s);
  EXPECT_TRUE(s.inside(origin));
  // Each voxel's depth: the distance to the nearest voxel outside (or beyond the grid).
  auto depth = [&](const Eigen::Vector3d& p) {
    double best = 1e300;
    for (int k = -1; k <= g.size[2]; ++k)
      for (int j = -1; j <= g.size[1]; ++j)
        for (int i = -1; i <= g.size[0]; ++i) {
          const bool beyond =
              i < 0 || j < 0 || k < 0 || i >= g.size[0] || j >= g.size[1] || k >= g.size[2];
          if (!beyond && mask->at(i, j, k) == 1) continue;
          best = std::min(best, (g.index_to_physical(Eigen::Vector3d(i, j, k)) - p).norm());
        }
    return best;
  };
  double deepest = 0;
  for (int k = 0; k < g.size[2]; ++k)
    for (int j = 0; j < g.size[1]; j += 3)  // every third row: the depths repeat round the ring
      for (int i = 0; i < g.size[0]; ++i)
        if (mask->at(i, j, k) == 1)
          deepest = std::max(deepest, depth(g.index_to_physical(Eigen::Vector3d(i, j, k))));
  EXPECT_NEAR(depth(origin), deepest, 1e-9);
  EXPECT_GE(depth(origin), 4.0);  // the middle of a 8 mm wall, the middle of 6 slices
  // A shape that holds its centre: the centre (an analytic body's; the horseshoe made whole).
  const Shape ellipsoid = make_shape("ellipsoid", {10, 20, 30}, {1, 2, 3});
  EXPECT_EQ(ray_origin_mm(ellipsoid), ellipsoid.centre_mm);
  auto ring = std::make_shared<LabelVolume>(*mask);
  for (int k = 1; k <= 6; ++k)
    for (int j = 0; j < g.size[1]; ++j)
      for (int i = 0; i < g.size[0]; ++i)
        if ((g.index_to_physical(Eigen::Vector3d(i, j, k)) - s.centre_mm).norm() < 12)
          ring->at(i, j, k) = 1;
  const Shape filled = make_mask_shape(ring);
  ASSERT_TRUE(filled.inside(filled.centre_mm));
  EXPECT_EQ(ray_origin_mm(filled), filled.centre_mm);
}

TEST(Shapes, AMaskShapeHasItsVoxelsBoundsAndCentroid) {
  ImageGeometry g;
  g.size = {10, 10, 10};
  g.spacing_mm = {1, 2, 3};
  g.origin_mm = {0, 0, 0};
  auto mask = std::make_shared<LabelVolume>(g);
  for (int k = 2; k <= 3; ++k)
    for (int j = 4; j <= 6; ++j)
      for (int i = 1; i <= 4; ++i)
        mask->at(i, j, k) = 1;
  const Shape s = make_mask_shape(mask);
  EXPECT_STREQ(s.kind_name(), "mask");
  // Voxel centres 1..4, 8..12, 6..9 mm; the organ's level lies up to a voxel beyond them.
  EXPECT_TRUE(s.bounds().min_mm.isApprox(Eigen::Vector3d(0, 6, 3)));
  EXPECT_TRUE(s.bounds().max_mm.isApprox(Eigen::Vector3d(5, 14, 12)));
  EXPECT_TRUE(s.size_mm.isApprox(Eigen::Vector3d(4, 6, 6)));  // the voxels' extent
  EXPECT_TRUE(s.centre_mm.isApprox(Eigen::Vector3d(2.5, 10, 7.5)));
  EXPECT_TRUE(s.inside({2.5, 10, 7.5}));
  EXPECT_FALSE(s.inside({8, 10, 7.5}));
  EXPECT_THROW(make_mask_shape(std::make_shared<LabelVolume>(g)), std::invalid_argument);
}

// Between thick slices a mask's organ is interpolated by shape (its signed distance at the
// level with the voxels' volume), as the fit's organ and the exports are: between a disk of
// radius 9 mm and one of 5 mm 3 mm above it, its radius at the midplane is about 7 mm, not
// the union that the 0.5 level of the mask's trilinear interpolation holds there.
TEST(Shapes, AMasksOrganBetweenThickSlicesIsInterpolatedByShape) {
  ImageGeometry g;
  g.size = {40, 40, 6};
  g.spacing_mm = {0.5, 0.5, 3};
  g.origin_mm = {-10, -10, -6};  // slices at z = -6, -3, 0, 3, 6, 9
  auto mask = std::make_shared<LabelVolume>(g);
  for (int k = 1; k <= 4; ++k)
    for (int j = 0; j < g.size[1]; ++j)
      for (int i = 0; i < g.size[0]; ++i) {
        const Eigen::Vector3d p = g.index_to_physical(Eigen::Vector3d(i, j, k));
        mask->at(i, j, k) = std::hypot(p.x(), p.y()) <= (p.z() < 1 ? 9.0 : 5.0);
      }
  const Shape s = make_mask_shape(mask);
  EXPECT_TRUE(inside_interpolated(*mask, {8, 0, 1.5}));  // the union at the midplane
  EXPECT_FALSE(s.inside({8, 0, 1.5}));
  EXPECT_TRUE(s.inside({6, 0, 1.5}));
  EXPECT_TRUE(s.inside({8.9, 0, 0}));  // on a slice, its contour
  EXPECT_FALSE(s.inside({9.6, 0, 0}));
  // Saved levels are taken as they are.
  SignedDistance::VolumeLevels levels{0.5 * s.distance->volume_level(), {0.01, 0.02, 0.03, 0.04}};
  const Shape saved = make_mask_shape(mask, levels);
  EXPECT_EQ(saved.distance->volume_level(), levels.level_mm);
  EXPECT_EQ(saved.distance->volume_levels().by_slice_phase_mm, levels.by_slice_phase_mm);
}

// inside_ball is never wrong: for balls about each analytic shape, every point sampled in
// a ball it places inside (outside) is inside (outside); and it does place balls, so that
// sampling a lattice can skip the voxels away from the surface.
TEST(Shapes, ABallTestIsNeverWrongAndPlacesBallsAwayFromTheSurface) {
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> uni(-1.0, 1.0);
  std::normal_distribution<double> gauss(0.0, 1.0);
  for (const char* kind : {"ellipsoid", "box", "egg", "lung"}) {
    const Shape s = make_shape(kind, {60, 40, 30}, {1, -2, 3});
    int placed = 0, unknown = 0;
    for (int b = 0; b < 3000; ++b) {
      const Eigen::Vector3d c =
          s.centre_mm + Eigen::Vector3d(40 * uni(rng), 30 * uni(rng), 25 * uni(rng));
      const double r = 0.05 + 6.0 * std::abs(uni(rng));
      const BallSide side = s.inside_ball(c, r);
      if (side == BallSide::unknown) {
        ++unknown;
        continue;
      }
      ++placed;
      for (int k = 0; k < 40; ++k) {  // on the ball's rim and within it
        Eigen::Vector3d dir(gauss(rng), gauss(rng), gauss(rng));
        dir.normalize();
        const Eigen::Vector3d p = c + (k < 20 ? r : r * std::abs(uni(rng))) * dir;
        ASSERT_EQ(s.inside(p), side == BallSide::inside) << kind << " ball " << b;
      }
    }
    EXPECT_GT(placed, 2000) << kind;
    EXPECT_GT(unknown, 50) << kind;  // near the surface
  }
}

// The same of a mask on a grid of thick slices turned about z, with a one-voxel hole:
// balls it places are on that side at every point (their rims most of all), balls in the
// hole or across the grid's edge are not placed inside.
TEST(Shapes, AMasksBallTestIsNeverWrong) {
  ImageGeometry g;
  g.size = {40, 36, 14};
  g.spacing_mm = {0.9, 0.9, 3};
  g.origin_mm = {-15, -12, -20};
  const double a = 0.3;
  g.direction << std::cos(a), -std::sin(a), 0, std::sin(a), std::cos(a), 0, 0, 0, 1;
  auto mask = std::make_shared<LabelVolume>(g);
  for (int k = 0; k < g.size[2]; ++k)
    for (int j = 0; j < g.size[1]; ++j)
      for (int i = 0; i < g.size[0]; ++i) {
        const Eigen::Vector3d u((i - 20) / 16.0, (j - 18) / 13.0, (k - 6) / 5.5);
        mask->at(i, j, k) = u.squaredNorm() <= 1 ? 1 : 0;
      }
  mask->at(20, 18, 6) = 0;
  for (int k = 3; k <= 9; ++k)  // a slab on the grid's -x face
    for (int j = 0; j < g.size[1]; ++j)
      for (int i = 0; i <= 2; ++i)
        mask->at(i, j, k) = 1;
  const Shape s = make_mask_shape(mask);
  std::mt19937 rng(11);
  std::uniform_real_distribution<double> uni(-1.0, 1.0);
  std::normal_distribution<double> gauss(0.0, 1.0);
  int inside = 0, outside = 0;
  for (int b = 0; b < 4000; ++b) {
    const Eigen::Vector3d c = g.index_to_physical(
        Eigen::Vector3d(20 + 24 * uni(rng), 18 + 22 * uni(rng), 6 + 9 * uni(rng)));
    const double r = 0.05 + 4.0 * std::abs(uni(rng));
    const BallSide side = s.inside_ball(c, r);
    if (side == BallSide::unknown) continue;
    (side == BallSide::inside ? inside : outside)++;
    for (int k = 0; k < 40; ++k) {
      Eigen::Vector3d dir(gauss(rng), gauss(rng), gauss(rng));
      dir.normalize();
      const Eigen::Vector3d p = c + (k < 20 ? r : r * std::abs(uni(rng))) * dir;
      ASSERT_EQ(s.inside(p), side == BallSide::inside) << "ball " << b;
    }
  }
  EXPECT_GT(inside, 50);
  EXPECT_GT(outside, 1000);
  EXPECT_NE(s.inside_ball(g.index_to_physical(Eigen::Vector3d(20, 18, 6)), 0.5),
            BallSide::inside);  // the hole
  const Eigen::Vector3d edge = g.index_to_physical(Eigen::Vector3d(0.5, 18, 6));
  EXPECT_TRUE(s.inside(edge));
  // Beyond the grid the organ goes on as its distance says (as the planning organ does: an
  // organ on the CT's last plane may go on beyond it).
  EXPECT_TRUE(s.inside(edge - 1.0 * g.direction.col(0)));
  EXPECT_EQ(s.inside_ball(edge, 1.0), BallSide::unknown);
  // Its extent holds that part too, and bounds() does not.
  const Aabb e = s.extent(), b = s.bounds();
  auto within = [](const Aabb& box, const Eigen::Vector3d& p) {
    return (p.array() >= box.min_mm.array()).all() && (p.array() <= box.max_mm.array()).all();
  };
  int beyond_bounds = 0, reached = 0;
  for (int n = 0; n < 20000; ++n) {
    const Eigen::Vector3d p = g.index_to_physical(
        Eigen::Vector3d(-12 + 14 * std::abs(uni(rng)), 18 + 20 * uni(rng), 6 + 5 * uni(rng)));
    if (!s.inside(p)) continue;
    ++reached;
    EXPECT_TRUE(within(e, p)) << p.transpose();
    beyond_bounds += !within(b, p);
  }
  EXPECT_GT(reached, 1000);
  EXPECT_GT(beyond_bounds, 100);
  EXPECT_LT(e.min_mm.x(), b.min_mm.x() - 1.0);
}

TEST(Shapes, AMasksExtentIsItsBoundsWhereItTouchesNoFace) {
  ImageGeometry g;
  g.size = {30, 30, 12};
  g.spacing_mm = {0.8, 0.8, 2.5};
  auto mask = std::make_shared<LabelVolume>(g);
  for (int k = 2; k < 10; ++k)
    for (int j = 5; j < 25; ++j)
      for (int i = 4; i < 22; ++i)
        mask->at(i, j, k) = 1;
  const Shape s = make_mask_shape(mask);
  EXPECT_EQ(s.extent().min_mm, s.bounds().min_mm);
  EXPECT_EQ(s.extent().max_mm, s.bounds().max_mm);
}

}  // namespace
}  // namespace organfit::geometry
