// The B-mode simulator and the edge search on a labelled sphere whose surface is known.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>

#include "organfit/ultrasound/boundary_points.h"
#include "organfit/ultrasound/simulator.h"

namespace organfit::ultrasound {
namespace {

// A sphere of radius 15 mm (label 2) at the origin in fat (label 1), a bone plate
// (HU 1000) at y <= -25 mm; the probe sits at y = +35 mm looking along -y.
constexpr double kRadius = 15.0;

TissueAt sphere_in_fat() {
  return [](const Eigen::Vector3d& p) {
    if (p.y() <= -25) return TissueSample{3, 1000.0f};
    if (p.norm() < kRadius) return TissueSample{2, 40.0f};
    return TissueSample{1, -95.0f};
  };
}

SimulatorOptions options(std::uint64_t seed) {
  SimulatorOptions o;
  o.probe_radius_mm = 5;
  o.max_depth_mm = 75;
  o.lateral_rays = o.elevation_rays = 121;
  o.seed = seed;
  o.echogenicity[1] = 0.9f, o.echogenicity[2] = 0.3f, o.echogenicity[3] = 1.0f;
  o.organ_label = 2;
  return o;
}

ProbePose probe() {
  ProbePose p;
  p.position_mm = Eigen::Vector3d(0, 35, 0);
  return p;
}

TEST(Simulator, IsDeterministicForASeedAndShadowsBehindBone) {
  const SimulatedUltrasound a = simulate_bmode(sphere_in_fat(), probe(), options(3));
  const SimulatedUltrasound b = simulate_bmode(sphere_in_fat(), probe(), options(3));
  const SimulatedUltrasound c = simulate_bmode(sphere_in_fat(), probe(), options(4));
  EXPECT_EQ(a.bmode, b.bmode);
  EXPECT_NE(a.bmode, c.bmode);
  // Mean grey in fat in front of the plate against behind it (depth 62-70 mm).
  const auto& g = a.geometry;
  double front = 0, behind = 0;
  long nf = 0, nb = 0;
  for (int k = 0; k < g.size[2]; ++k)
    for (int j = 0; j < g.size[1]; ++j)
      for (int i = 0; i < g.size[0]; ++i) {
        const auto v = static_cast<size_t>(g.linear_index(i, j, k));
        if (!a.in_view[v]) continue;
        const Eigen::Vector3d p = g.index_to_physical(Eigen::Vector3d(i, j, k));
        if (p.y() > -22 && p.y() < -18 && std::abs(p.x()) > 20) front += a.bmode[v], ++nf;
        if (p.y() < -28) behind += a.bmode[v], ++nb;
      }
  ASSERT_GT(nf, 100);
  ASSERT_GT(nb, 100);
  EXPECT_GT(front / nf, 150.0);
  EXPECT_LT(behind / nb, 5.0);  // the floor of the dynamic range: shadow
}

TEST(Simulator, TrueBoundaryIsTheVisibleSphereSurface) {
  const SimulatedUltrasound s = simulate_bmode(sphere_in_fat(), probe(), options(1));
  ASSERT_GT(s.true_boundary_mm.size(), 1000u);
  for (const auto& p : s.true_boundary_mm)
    ASSERT_NEAR(p.norm(), kRadius, 0.3) << p.transpose();
}

TEST(Simulator, RefusesAPoseWhoseAxesAreNotPerpendicular) {
  ProbePose p = probe();
  p.lateral = Eigen::Vector3d(0, 1, 0);
  EXPECT_THROW(simulate_bmode(sphere_in_fat(), p, options(1)), std::invalid_argument);
}

TEST(BoundaryPoints, FindTheSphereInSpeckle) {
  const SimulatedUltrasound s = simulate_bmode(sphere_in_fat(), probe(), options(5));
  BoundaryOptions o;
  o.centre_mm = Eigen::Vector3d(1, -1, 0.5);  // not quite the centre
  o.r_max_mm = 25;
  o.target_count = 87;
  const std::vector<float> intensity(s.bmode.begin(), s.bmode.end());
  const BoundaryResult r = boundary_points(s.geometry, intensity, &s.in_view, o);
  ASSERT_EQ(r.points.size(), 87u);
  std::vector<double> err;
  for (const auto& p : r.points)
    err.push_back(std::abs(p.p_mm.norm() - kRadius));
  std::sort(err.begin(), err.end());
  EXPECT_LT(err[err.size() / 2], 0.7);       // median
  EXPECT_LT(err[err.size() * 9 / 10], 1.5);  // 90th percentile
  for (const auto& p : r.points)
    EXPECT_TRUE(p.confidence >= 0.1 && p.confidence <= 1.0);
}

TEST(BoundaryPoints, APriorBandKeepsTheSearchNearTheModel) {
  const SimulatedUltrasound s = simulate_bmode(sphere_in_fat(), probe(), options(6));
  BoundaryOptions o;
  o.r_max_mm = 25;
  o.target_count = 0;
  o.prior_inside = [](const Eigen::Vector3d& p) { return p.norm() < 13.0; };  // 2 mm small
  o.band_mm = 4;
  const std::vector<float> intensity(s.bmode.begin(), s.bmode.end());
  const BoundaryResult r = boundary_points(s.geometry, intensity, &s.in_view, o);
  ASSERT_GT(r.points.size(), 500u);
  for (const auto& p : r.points)
    ASSERT_LE(p.p_mm.norm(), 13.0 + 4.0 + 0.5);
}

TEST(BoundaryPoints, RefuseACentreOutsideTheVolume) {
  geometry::ImageGeometry g;
  g.size = {10, 10, 10};
  const std::vector<float> v(1000, 0.f);
  BoundaryOptions o;
  o.centre_mm = Eigen::Vector3d(50, 0, 0);
  EXPECT_THROW(boundary_points(g, v, nullptr, o), std::invalid_argument);
  EXPECT_THROW(boundary_points(g, std::vector<float>(5), nullptr, BoundaryOptions{}),
               std::invalid_argument);
}

}  // namespace
}  // namespace organfit::ultrasound
