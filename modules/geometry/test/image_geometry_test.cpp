#include "organfit/geometry/image_geometry.h"

#include <gtest/gtest.h>

#include <Eigen/Geometry>

namespace organfit::geometry {
namespace {

TEST(ImageGeometry, IndexPhysicalRoundTripWithRotatedDirection) {
  ImageGeometry g;
  g.size = {10, 12, 5};
  g.spacing_mm = {0.9, 0.8, 3.0};
  g.origin_mm = {-100, 50, 20};
  g.direction = Eigen::AngleAxisd(0.3, Eigen::Vector3d(1, 2, 3).normalized()).toRotationMatrix();
  const Eigen::Vector3d idx(3.5, 7.25, 2);
  EXPECT_LT((g.physical_to_index(g.index_to_physical(idx)) - idx).norm(), 1e-12);
  // One step along k moves spacing_k mm along the third direction column.
  const Eigen::Vector3d step = g.index_to_physical({0, 0, 1}) - g.index_to_physical({0, 0, 0});
  EXPECT_NEAR(step.norm(), 3.0, 1e-12);
  EXPECT_LT((step.normalized() - g.direction.col(2)).norm(), 1e-12);
}

TEST(ImageGeometry, IndexRangeOfABoxIsClampedPaddedAndEmptyOffTheGrid) {
  ImageGeometry g;
  g.size = {20, 10, 8};
  g.spacing_mm = Eigen::Vector3d(1.0, 2.0, 2.5);
  g.origin_mm = Eigen::Vector3d(-10, 0, 5);
  // x 2.5..5.2 mm -> index 12.5..15.2; y 3..7 -> 1.5..3.5; z 5..10 -> 0..2.
  const IndexRange r = index_range(g, {{2.5, 3, 5}, {5.2, 7, 10}});
  EXPECT_EQ(r.lo, (std::array<int, 3>{12, 1, 0}));
  EXPECT_EQ(r.hi, (std::array<int, 3>{16, 4, 2}));
  const IndexRange padded = index_range(g, {{2.5, 3, 5}, {5.2, 7, 10}}, 1);
  EXPECT_EQ(padded.lo, (std::array<int, 3>{11, 0, 0}));
  EXPECT_EQ(padded.hi, (std::array<int, 3>{17, 5, 3}));
  EXPECT_FALSE(r.empty());
  EXPECT_TRUE(index_range(g, {{1e9, 3, 5}, {2e9, 7, 10}}).empty());
  EXPECT_TRUE(index_range(g, {{-1e300, 3, 5}, {-1e299, 7, 10}}).empty());
  const IndexRange all = index_range(g, {{-1e300, -1e300, -1e300}, {1e300, 1e300, 1e300}});
  EXPECT_EQ(all.lo, (std::array<int, 3>{0, 0, 0}));
  EXPECT_EQ(all.hi, (std::array<int, 3>{19, 9, 7}));
}

TEST(LabelVolume, CountsVolumeAndPhysicalLookup) {
  ImageGeometry g;
  g.size = {4, 4, 4};
  g.spacing_mm = {0.5, 0.5, 2.0};
  LabelVolume v(g);
  v.at(1, 2, 3) = 1;
  v.at(0, 0, 0) = 1;
  EXPECT_EQ(v.count(1), 2);
  EXPECT_DOUBLE_EQ(v.volume_mm3(1), 2 * 0.5);
  EXPECT_EQ(v.at_physical({0.5, 1.0, 6.0}), 1);
  EXPECT_EQ(v.at_physical({-5, 0, 0}), 0);
  const Aabb b = g.bounds_mm();
  EXPECT_EQ(b.max_mm, Eigen::Vector3d(1.5, 1.5, 6.0));
}

}  // namespace
}  // namespace organfit::geometry

namespace organfit::geometry {
namespace {

// The box of a box's image: exact for an affine map (a rotation by 90 degrees about z and
// a shift here), the corners' hull for any map.
TEST(ImageOfBox, IsTheImageOfTheBoxUnderAnAffineMap) {
  const Aabb box{{0, 0, 0}, {2, 4, 6}};
  const Aabb r = image_of_box(box, [](const Eigen::Vector3d& p) -> Eigen::Vector3d {
    return Eigen::Vector3d(-p.y(), p.x(), p.z()) + Eigen::Vector3d(10, 0, -1);
  });
  EXPECT_TRUE(r.min_mm.isApprox(Eigen::Vector3d(6, 0, -1)));
  EXPECT_TRUE(r.max_mm.isApprox(Eigen::Vector3d(10, 2, 5)));
}

}  // namespace
}  // namespace organfit::geometry
