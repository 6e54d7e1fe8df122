#include "organfit/fitting/global_map_posterior.h"

#include <gtest/gtest.h>

#include <cmath>
#include <random>

#include "ellipsoid_mask.h"

namespace organfit::fitting {
namespace {

const Eigen::Vector3d& kSemi = test::kEllipsoidSemiAxesMm;

/// `count` points on the ellipsoid, all over it or (`plane`) on its section z = 0.
std::vector<AttractivePoint> points_on_ellipsoid(int count, bool plane, unsigned seed) {
  std::mt19937 rng(seed);
  std::normal_distribution<double> g;
  std::vector<AttractivePoint> pts;
  for (int k = 0; k < count; ++k) {
    Eigen::Vector3d d(g(rng), g(rng), plane ? 0.0 : g(rng));
    pts.push_back({kSemi.cwiseProduct(d.normalized()), 1.0});
  }
  return pts;
}

constexpr double kNoise = 0.5, kMotion = 4.0, kLocal = 1.7, kLength = 7.0, kMads = 3.0;  // mm

// Points all over the organ fix its place to about a third of the prior's sd everywhere
// (200 points, but the local change they also see is correlated over l); points on one
// plane (one 2D frame) leave it nearly as free as the prior does, most of all far from
// the plane.
TEST(GlobalMapPosterior, PointsOverTheOrganFixTheMapAndPointsOnOnePlaneDoNot) {
  const SurfaceSamples surface = test::ellipsoid_mask_surface();
  const GlobalMap identity;
  const GlobalMapPosterior over =
      global_map_posterior(identity, surface, points_on_ellipsoid(200, false, 1), kNoise, kMotion,
                           kLocal, kLength, kMads);
  ASSERT_EQ(over.variance_mm2.size(), surface.points.cols());
  EXPECT_LT(std::sqrt(over.variance_mm2.maxCoeff()), 0.35 * kMotion);

  const GlobalMapPosterior plane = global_map_posterior(
      identity, surface, points_on_ellipsoid(87, true, 2), kNoise, kMotion, kLocal, kLength, kMads);
  EXPECT_GT(std::sqrt(plane.variance_mm2.maxCoeff()), 0.75 * kMotion);
  double at_plane = 0, at_poles = 0;
  int n_plane = 0, n_poles = 0;
  for (Eigen::Index j = 0; j < surface.points.cols(); ++j) {
    const double z = surface.points(2, j);
    if (std::abs(z) < 2) at_plane += plane.variance_mm2(j), ++n_plane;
    if (std::abs(z) > 15) at_poles += plane.variance_mm2(j), ++n_poles;
  }
  ASSERT_GT(n_plane, 0);
  ASSERT_GT(n_poles, 0);
  EXPECT_GT(std::sqrt(at_poles / n_poles), 2 * std::sqrt(at_plane / n_plane));
  EXPECT_GT(std::sqrt(plane.variance_mm2.maxCoeff()), 2 * std::sqrt(over.variance_mm2.maxCoeff()));
}

// With no points, the posterior is the prior: a sample's variance is its move's under the
// prior on det A = 1. At a pole (0, 0, c) of the
// ellipsoid, normal z: g = (e_z, e_z (x - c)^T), its move dc'_z + dA_zz c: tau^2 + (tau / R)^2
// c^2 less what the constraint takes from dA_zz (tr dA = 0: dA_zz's variance 2/3 of the
// prior's).
TEST(GlobalMapPosterior, WithoutPointsIsThePrior) {
  const SurfaceSamples surface = test::ellipsoid_mask_surface();
  const GlobalMapPosterior none =
      global_map_posterior(GlobalMap{}, surface, {}, kNoise, kMotion, kLocal, kLength, kMads);
  const Eigen::Vector3d c = surface.points.rowwise().mean();
  const double r2 = (surface.points.colwise() - c).colwise().squaredNorm().mean();
  Eigen::Index top = 0;
  surface.points.row(2).maxCoeff(&top);
  const Eigen::Vector3d x = surface.points.col(top) - c;
  const Eigen::Vector3d n = surface.normals.col(top);
  // var = tau^2 |n|^2 + (tau^2 / R^2) (|n|^2 |x|^2 - (n^T x)^2 / 3) for the trace-free dA.
  const double expected =
      kMotion * kMotion * (1 + (x.squaredNorm() - std::pow(n.dot(x), 2) / 3) / r2);
  EXPECT_NEAR(none.variance_mm2(top), expected, 1e-9 * expected);
}

}  // namespace
}  // namespace organfit::fitting
