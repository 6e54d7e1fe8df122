// The Gaussian-process posterior of fitting/surface_uncertainty.h against its closed forms.
#include "organfit/fitting/surface_uncertainty.h"

#include <gtest/gtest.h>

#include <cmath>

namespace organfit::fitting {
namespace {

TEST(SurfaceUncertainty, OnePointHasTheClosedFormAtItAndThePriorFarAway) {
  SurfaceUncertaintyOptions o;
  o.prior_sd_mm = 3.0, o.length_mm = 8.0, o.noise_sd_mm = 0.5;
  const SurfaceUncertainty u({Eigen::Vector3d(1, 2, 3)}, o);
  // At the point: s^2 - s^4 / (s^2 + n^2) = s^2 n^2 / (s^2 + n^2).
  EXPECT_NEAR(u.sd_mm(Eigen::Vector3d(1, 2, 3)), std::sqrt(9 * 0.25 / 9.25), 1e-12);
  // At distance d: s^2 - s^4 exp(-d^2 / l^2) / (s^2 + n^2).
  const double d = 6, k = 9 * std::exp(-d * d / (2 * 64.0));
  EXPECT_NEAR(u.sd_mm(Eigen::Vector3d(1 + d, 2, 3)), std::sqrt(9 - k * k / 9.25), 1e-12);
  EXPECT_NEAR(u.sd_mm(Eigen::Vector3d(200, 2, 3)), 3.0, 1e-12);
  EXPECT_NEAR(u.nearest_point_mm(Eigen::Vector3d(1, 2, 7)), 4.0, 1e-12);
}

TEST(SurfaceUncertainty, RisesMonotonicallyAwayFromThePointsAndFallsWithMorePoints) {
  SurfaceUncertaintyOptions o;
  std::vector<Eigen::Vector3d> row;
  for (int i = 0; i < 10; ++i)
    row.emplace_back(2.0 * i, 0, 0);
  const SurfaceUncertainty u(row, o);
  double last = 0;
  for (double y = 0; y <= 40; y += 2) {
    const double s = u.sd_mm(Eigen::Vector3d(9, y, 0));
    EXPECT_GE(s, last - 1e-12) << y;
    last = s;
  }
  EXPECT_NEAR(last, o.prior_sd_mm, 1e-6);
  // Ten points 2 mm apart know the surface there better than one does.
  const SurfaceUncertainty one({row[4]}, o);
  EXPECT_LT(u.sd_mm(row[4]), one.sd_mm(row[4]));
  EXPECT_GT(u.sd_mm(row[4]), 0.0);
}

TEST(SurfaceUncertainty, ManyPointsAreBinnedWithTheirNoiseShared) {
  // 8 points at one place are one observation of noise n / sqrt(8).
  SurfaceUncertaintyOptions o;
  o.max_points = 1;
  const SurfaceUncertainty binned(std::vector<Eigen::Vector3d>(8, Eigen::Vector3d(1, 1, 1)), o);
  const double s2 = 4, n2 = 0.25 / 8;
  EXPECT_NEAR(binned.sd_mm(Eigen::Vector3d(1, 1, 1)), std::sqrt(s2 * n2 / (s2 + n2)), 1e-9);
  // A dense sheet of 10,000 points: a few hundred observations, sigma small on it, the
  // prior far from it; the nearest point is still among all of them.
  std::vector<Eigen::Vector3d> sheet;
  for (int i = 0; i < 100; ++i)
    for (int j = 0; j < 100; ++j)
      sheet.emplace_back(0.5 * i, 0.5 * j, 0);
  const SurfaceUncertainty u(sheet, SurfaceUncertaintyOptions{});
  EXPECT_LT(u.sd_mm(Eigen::Vector3d(25, 25, 0)), 0.1);
  EXPECT_NEAR(u.sd_mm(Eigen::Vector3d(25, 25, 100)), 2.0, 1e-9);
  EXPECT_NEAR(u.nearest_point_mm(Eigen::Vector3d(0.5, 0.5, 3)), 3.0, 1e-12);
}

TEST(SurfaceUncertainty, AddsTheModelsResolutionInQuadrature) {
  // One point: at it, s^2 n^2 / (s^2 + n^2) + r^2; far away, s^2 + r^2; a dense sheet of
  // points no longer takes sigma below r.
  SurfaceUncertaintyOptions o;
  o.prior_sd_mm = 3.0, o.length_mm = 8.0, o.noise_sd_mm = 0.5, o.resolution_sd_mm = 0.4;
  const SurfaceUncertainty u({Eigen::Vector3d(1, 2, 3)}, o);
  EXPECT_NEAR(u.sd_mm(Eigen::Vector3d(1, 2, 3)), std::sqrt(9 * 0.25 / 9.25 + 0.16), 1e-12);
  EXPECT_NEAR(u.sd_mm(Eigen::Vector3d(200, 2, 3)), std::sqrt(9 + 0.16), 1e-12);
  EXPECT_NEAR(u.far_sd_mm(), std::sqrt(9 + 0.16), 1e-12);
  EXPECT_NEAR(SurfaceUncertainty({}, o).sd_mm({0, 0, 0}), std::sqrt(9 + 0.16), 1e-12);
  std::vector<Eigen::Vector3d> sheet;
  for (int i = 0; i < 100; ++i)
    for (int j = 0; j < 100; ++j)
      sheet.emplace_back(0.5 * i, 0.5 * j, 0);
  const double on_sheet = SurfaceUncertainty(sheet, o).sd_mm(Eigen::Vector3d(25, 25, 0));
  EXPECT_GE(on_sheet, 0.4);
  EXPECT_LT(on_sheet, 0.41);
  o.resolution_sd_mm = -0.1;
  EXPECT_THROW(SurfaceUncertainty({}, o), std::invalid_argument);
}

TEST(SurfaceUncertainty, RefusesNonPositiveOptions) {
  SurfaceUncertaintyOptions o;
  o.length_mm = 0;
  EXPECT_THROW(SurfaceUncertainty({}, o), std::invalid_argument);
  o = {};
  o.noise_sd_mm = std::nan("");
  EXPECT_THROW(SurfaceUncertainty({}, o), std::invalid_argument);
  EXPECT_DOUBLE_EQ(SurfaceUncertainty({}, SurfaceUncertaintyOptions{}).sd_mm({0, 0, 0}), 2.0);
}

}  // namespace
}  // namespace organfit::fitting
