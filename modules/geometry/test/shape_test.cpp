#include "organfit/geometry/shape.h"

#include <gtest/gtest.h>

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
  // Voxel centres 1..4, 8..12, 6..9 mm; bounds half a voxel beyond them.
  EXPECT_TRUE(s.bounds().min_mm.isApprox(Eigen::Vector3d(0.5, 7, 4.5)));
  EXPECT_TRUE(s.bounds().max_mm.isApprox(Eigen::Vector3d(4.5, 13, 10.5)));
  EXPECT_TRUE(s.centre_mm.isApprox(Eigen::Vector3d(2.5, 10, 7.5)));
  EXPECT_TRUE(s.inside({2.5, 10, 7.5}));
  EXPECT_FALSE(s.inside({8, 10, 7.5}));
  EXPECT_THROW(make_mask_shape(std::make_shared<LabelVolume>(g)), std::invalid_argument);
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
  Shape m = make_shape("ellipsoid", {10, 10, 10}, {0, 0, 0});
  m.mask = std::make_shared<LabelVolume>();
  EXPECT_EQ(m.inside_ball({0, 0, 0}, 0.1), BallSide::unknown);  // masks: point by point
}

}  // namespace
}  // namespace organfit::geometry
