#include "organfit/geometry/signed_distance.h"

#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <cmath>

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

}  // namespace
}  // namespace organfit::geometry
