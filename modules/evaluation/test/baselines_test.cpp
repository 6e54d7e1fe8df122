// The baselines of bench fit recover what they should on exact data.
#include "organfit/evaluation/baselines.h"

#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <random>

namespace organfit::evaluation {
namespace {

Eigen::Matrix3Xd ellipsoid_samples(int n, unsigned seed) {
  std::mt19937 rng(seed);
  std::normal_distribution<double> g(0, 1);
  Eigen::Matrix3Xd s(3, n);
  for (int i = 0; i < n; ++i) {
    Eigen::Vector3d v(g(rng), g(rng), g(rng));
    v.normalize();
    s.col(i) = Eigen::Vector3d(20 * v.x(), 14 * v.y(), 10 * v.z());
  }
  return s;
}

TEST(SimilarityIcp, RecoversAKnownSimilarityFromSurfacePoints) {
  const Eigen::Matrix3Xd surface = ellipsoid_samples(1500, 1);
  const Eigen::Matrix3d r =
      Eigen::AngleAxisd(0.1, Eigen::Vector3d(1, 2, 3).normalized()).toRotationMatrix();
  const Eigen::Vector3d t(1.5, -2, 0.5);
  const double s = 1.08;
  // The points: a subset of the surface moved by the similarity.
  Eigen::Matrix3Xd points(3, 200);
  for (int i = 0; i < 200; ++i)
    points.col(i) = s * r * surface.col(7 * i) + t;
  const PointMap map = similarity_icp(surface, points, 50);
  for (int i = 0; i < 200; i += 17)
    EXPECT_LT((map(surface.col(7 * i)) - points.col(i)).norm(), 0.05);
}

TEST(CoherentPointDrift, PullsTheSurfaceOntoStretchedPoints) {
  const Eigen::Matrix3Xd surface = ellipsoid_samples(300, 2);
  Eigen::Matrix3Xd points = ellipsoid_samples(120, 3);
  points.row(0) *= 1.2;  // stretched along x
  const Eigen::Matrix3Xd dense =
      ellipsoid_samples(4000, 4);  // the surface, densely: distances without a sampling floor
  auto mean_distance = [&](const PointMap& map) {
    Eigen::Matrix3Xd moved(3, dense.cols());
    for (Eigen::Index j = 0; j < dense.cols(); ++j)
      moved.col(j) = map(dense.col(j));
    double sum = 0;
    for (Eigen::Index i = 0; i < points.cols(); ++i) {
      double best = 1e300;
      for (Eigen::Index j = 0; j < moved.cols(); ++j)
        best = std::min(best, (moved.col(j) - points.col(i)).norm());
      sum += best;
    }
    return sum / static_cast<double>(points.cols());
  };
  const double before = mean_distance([](const Eigen::Vector3d& p) { return p; });
  const double after = mean_distance(coherent_point_drift(surface, points, CpdOptions{}));
  EXPECT_GT(before, 1.0);
  EXPECT_LT(after, 0.4 * before);
}

}  // namespace
}  // namespace organfit::evaluation
