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

TEST(SurfaceUncertainty, ManyPointsAreSeenAtTheirOwnLengthNotTheBinsSpacing) {
  // 40,000 points 0.5 mm apart on a 100 mm sheet, l = 2 mm: every place on the sheet has
  // points within l/4, so sigma there is small wherever it is asked (binning the sheet into
  // a few hundred cells 5 mm wide left it at the prior between their centres).
  SurfaceUncertaintyOptions o;
  o.length_mm = 2.0;
  std::vector<Eigen::Vector3d> sheet;
  for (int i = 0; i < 200; ++i)
    for (int j = 0; j < 200; ++j)
      sheet.emplace_back(0.5 * i, 0.5 * j, 0);
  const SurfaceUncertainty u(sheet, o);
  for (const Eigen::Vector3d& x : {Eigen::Vector3d(33.3, 71.7, 0), Eigen::Vector3d(2.6, 97.9, 0),
                                   Eigen::Vector3d(50.1, 50.2, 0)})
    EXPECT_LT(u.sd_mm(x), 0.2) << x.transpose();
  EXPECT_NEAR(u.sd_mm(Eigen::Vector3d(50, 50, 30)), 2.0, 1e-9);
}

TEST(SurfaceUncertainty, TheNearestObservationsGiveNoNarrowerAPosteriorThanAll) {
  // 900 points 2 mm apart (one a cell of l/2 = 1.5 mm): the posterior given the 64 nearest
  // is never narrower than given all 900 (without residuals: the variance alone), and with
  // residuals (the mean too) within 2% of it.
  SurfaceUncertaintyOptions all, local;
  all.length_mm = local.length_mm = 3.0;
  all.max_points = 1000, local.max_points = 10;
  std::vector<Eigen::Vector3d> points;
  std::vector<double> residuals;
  for (int i = 0; i < 30; ++i)
    for (int j = 0; j < 30; ++j)
      points.emplace_back(2.0 * i + 0.25, 2.0 * j + 0.25, 0.1 * i),
          residuals.push_back(0.3 * std::sin(0.7 * i + 0.3 * j));
  const SurfaceUncertainty exact(points, all, residuals), near(points, local, residuals);
  const SurfaceUncertainty exact_variance(points, all), near_variance(points, local);
  for (double x = -4; x <= 64; x += 3.7)
    for (double z : {0.0, 2.0, 6.0}) {
      const Eigen::Vector3d q(x, 0.5 * x + 7, z + 0.05 * x);
      EXPECT_GE(near_variance.sd_mm(q), exact_variance.sd_mm(q) - 1e-12) << q.transpose();
      EXPECT_LT(near_variance.sd_mm(q), 1.02 * exact_variance.sd_mm(q)) << q.transpose();
      EXPECT_NEAR(near.sd_mm(q), exact.sd_mm(q), 0.02 * exact.sd_mm(q)) << q.transpose();
    }
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

TEST(SurfaceUncertainty, AddsThePosteriorMeanOfTheResidualsTheFitLeft) {
  // One point the fit left y = 2 mm off: at it, m = s^2 / (s^2 + n^2) y and the spread is
  // sqrt(m^2 + s^2 n^2 / (s^2 + n^2)); far away m vanishes and the prior is left. Zero
  // residuals are no residuals.
  SurfaceUncertaintyOptions o;
  o.prior_sd_mm = 3.0, o.length_mm = 8.0, o.noise_sd_mm = 0.5;
  const Eigen::Vector3d p(1, 2, 3);
  const SurfaceUncertainty u({p}, o, {2.0});
  const double m = 9 / 9.25 * 2.0;
  EXPECT_NEAR(u.sd_mm(p), std::sqrt(m * m + 9 * 0.25 / 9.25), 1e-12);
  const double d = 6, k = 9 * std::exp(-d * d / (2 * 64.0));
  EXPECT_NEAR(u.sd_mm(p + Eigen::Vector3d(d, 0, 0)),
              std::sqrt(std::pow(k / 9.25 * 2.0, 2) + 9 - k * k / 9.25), 1e-12);
  EXPECT_NEAR(u.sd_mm(Eigen::Vector3d(200, 2, 3)), 3.0, 1e-12);
  EXPECT_EQ(SurfaceUncertainty({p}, o, {0.0}).sd_mm(p), SurfaceUncertainty({p}, o).sd_mm(p));
  // Binned, the residuals are averaged with the positions: 8 points at one place, residuals
  // 1 to 8 mm, are one observation of 4.5 mm with noise n / sqrt(8).
  o.max_points = 1;
  const SurfaceUncertainty binned(std::vector<Eigen::Vector3d>(8, p), o, {1, 2, 3, 4, 5, 6, 7, 8});
  const double n2 = 0.25 / 8, mb = 9 / (9 + n2) * 4.5;
  EXPECT_NEAR(binned.sd_mm(p), std::sqrt(mb * mb + 9 * n2 / (9 + n2)), 1e-9);
  EXPECT_THROW(SurfaceUncertainty({p}, o, {1.0, 2.0}), std::invalid_argument);
  EXPECT_THROW(SurfaceUncertainty({p}, o, {std::nan("")}), std::invalid_argument);
}

TEST(SurfaceUncertainty, ThePriorWidensWhereItsVarianceFieldSaysSo) {
  // u^2 = 5 mm^2 about (0, 0, 0), 0 about (40, 0, 0): s(x)^2 = s^2 + u^2 of the nearest place.
  SurfaceUncertaintyOptions o;
  o.prior_sd_mm = 2.0, o.length_mm = 8.0, o.noise_sd_mm = 0.5, o.resolution_sd_mm = 0.3;
  PriorVarianceField u;
  u.at_mm = (Eigen::Matrix3Xd(3, 2) << 0, 40, 0, 0, 0, 0).finished();
  u.variance_mm2 = Eigen::Vector2d(5, 0);
  const SurfaceUncertainty none({}, o, {}, u);
  EXPECT_NEAR(none.sd_mm(Eigen::Vector3d(5, 3, 0)), std::sqrt(4 + 5 + 0.09), 1e-12);
  EXPECT_NEAR(none.sd_mm(Eigen::Vector3d(35, -3, 0)), std::sqrt(4 + 0.09), 1e-12);
  EXPECT_NEAR(none.far_sd_mm(), std::sqrt(4 + 5 + 0.09), 1e-12);
  // One point at (1, 0, 0): at it s_p^2 n^2 / (s_p^2 + n^2) + r^2 with s_p^2 = 9; at 6 mm
  // from it towards the other place (still nearer the first), s_x = s_p.
  const Eigen::Vector3d p(1, 0, 0);
  const SurfaceUncertainty one({p}, o, {}, u);
  EXPECT_NEAR(one.sd_mm(p), std::sqrt(9 * 0.25 / 9.25 + 0.09), 1e-12);
  const double k = 9 * std::exp(-36 / (2 * 64.0));
  EXPECT_NEAR(one.sd_mm(Eigen::Vector3d(7, 0, 0)), std::sqrt(9 - k * k / 9.25 + 0.09), 1e-12);
  // Beyond the middle, s_x = s and k(x, p) = s s_p exp(-d^2 / 2 l^2).
  const double kb = 2 * 3 * std::exp(-22.0 * 22.0 / (2 * 64.0));
  EXPECT_NEAR(one.sd_mm(Eigen::Vector3d(23, 0, 0)), std::sqrt(4 - kb * kb / 9.25 + 0.09), 1e-12);
  u.variance_mm2[1] = -1;
  EXPECT_THROW(SurfaceUncertainty({}, o, {}, u), std::invalid_argument);
  u.variance_mm2 = Eigen::Vector3d(1, 1, 1);
  EXPECT_THROW(SurfaceUncertainty({}, o, {}, u), std::invalid_argument);
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
