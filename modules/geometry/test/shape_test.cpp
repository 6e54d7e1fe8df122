#include "organfit/geometry/shape.h"

#include <gtest/gtest.h>

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

}  // namespace
}  // namespace organfit::geometry
