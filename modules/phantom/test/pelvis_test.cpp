#include "organfit/phantom/pelvis.h"

#include <gtest/gtest.h>

#include <cmath>

namespace organfit::phantom {
namespace {

PelvisOptions small_options(std::uint64_t seed) {
  PelvisOptions o;
  o.seed = seed;
  o.columns = o.rows = 100;  // 4 mm pixels over the same 400 mm field
  o.pixel_mm = 4.0;
  o.slices = 28;
  o.slice_mm = 5.0;
  return o;
}

TEST(PelvisPhantom, ProstateIsAbout35Cm3AtTheDefaultResolution) {
  const PelvisPhantom ph = make_pelvis_phantom(PelvisOptions{});
  EXPECT_NEAR(ph.labels.volume_mm3(kProstate) / 1000.0, 35.0, 1.0);
  EXPECT_EQ(ph.geometry.size[0], 320);
  EXPECT_EQ(ph.labels.at_physical(Eigen::Vector3d(0, 0, 0)), kProstate);
}

TEST(PelvisPhantom, OrgansSitWhereTheAnatomySays) {
  EXPECT_EQ(pelvis_label_at({0, 0, 0}), kProstate);
  EXPECT_EQ(pelvis_label_at({0, 0, 30}), kBladder);       // bladder above the base
  EXPECT_EQ(pelvis_label_at({0, 38 + 13, 0}), kRectum);   // rectal wall behind
  EXPECT_EQ(pelvis_label_at({0, 20.5, 0}), kSoftTissue);  // fat between prostate and rectum
  EXPECT_EQ(pelvis_label_at({98, 8, -5}), kFemurLeft);    // +x is the patient's left
  EXPECT_EQ(pelvis_label_at({-98, 8, -5}), kFemurRight);
  EXPECT_EQ(pelvis_label_at({0, -40 - 5, 0}), kPelvicBone);  // pubis in front
  EXPECT_EQ(pelvis_label_at({0, 200, 0}), kAir);
}

TEST(PelvisPhantom, NoiseHasTheRequestedSpreadAndFollowsTheSeed) {
  const PelvisPhantom a = make_pelvis_phantom(small_options(7)),
                      b = make_pelvis_phantom(small_options(7)),
                      c = make_pelvis_phantom(small_options(8));
  EXPECT_EQ(a.hu, b.hu);
  EXPECT_NE(a.hu, c.hu);
  EXPECT_EQ(a.labels.labels, c.labels.labels);  // the anatomy does not depend on the seed
  // Interior fat voxels (all six neighbours fat: no partial volume): mean -95 HU,
  // deviation = noise.
  double sum = 0, sum2 = 0;
  long n = 0;
  const auto& g = a.geometry;
  for (int k = 1; k + 1 < g.size[2]; ++k)
    for (int j = 1; j + 1 < g.size[1]; ++j)
      for (int i = 1; i + 1 < g.size[0]; ++i) {
        bool all_fat = a.labels.at(i, j, k) == kSoftTissue;
        for (int d = -1; d <= 1; d += 2)
          all_fat = all_fat && a.labels.at(i + d, j, k) == kSoftTissue &&
                    a.labels.at(i, j + d, k) == kSoftTissue &&
                    a.labels.at(i, j, k + d) == kSoftTissue;
        if (!all_fat) continue;
        const double v = a.hu[static_cast<size_t>(g.linear_index(i, j, k))];
        sum += v, sum2 += v * v, ++n;
      }
  ASSERT_GT(n, 10000);
  const double mean = sum / n, sd = std::sqrt(sum2 / n - mean * mean);
  EXPECT_NEAR(mean, -95.0, 0.5);
  EXPECT_NEAR(sd, 12.0, 0.3);
}

TEST(PelvisPhantom, TrueContoursEncloseTheTrueLabelsArea) {
  const PelvisPhantom ph = make_pelvis_phantom(PelvisOptions{});
  const PelvisStructure& prostate = pelvis_structures()[3];
  ASSERT_EQ(prostate.name, "Prostate");
  const auto contours = pelvis_true_contours(ph.labels, prostate);
  ASSERT_FALSE(contours.empty());
  // The area inside each slice's contours (shoelace) against the label's voxel area:
  // the contours are traced on a 4x finer grid, so they agree to the boundary's error.
  double contour_volume = 0;
  for (const auto& c : contours) {
    double area = 0;
    for (size_t v = 0; v < c.points_mm.size(); ++v) {
      const auto& p = c.points_mm[v];
      const auto& q = c.points_mm[(v + 1) % c.points_mm.size()];
      area += p.x() * q.y() - q.x() * p.y();
    }
    contour_volume += std::abs(area) / 2 * ph.geometry.spacing_mm[2];
    EXPECT_NEAR(c.points_mm.front().z(),
                ph.geometry.index_to_physical(Eigen::Vector3d(0, 0, c.k)).z(), 1e-9);
  }
  EXPECT_NEAR(contour_volume / ph.labels.volume_mm3(kProstate), 1.0, 0.02);
}

TEST(PelvisPhantom, RefusesDegenerateGrids) {
  PelvisOptions o;
  o.slices = 2;
  EXPECT_THROW(make_pelvis_phantom(o), std::invalid_argument);
  o = PelvisOptions{};
  o.pixel_mm = 0;
  EXPECT_THROW(make_pelvis_phantom(o), std::invalid_argument);
}

}  // namespace
}  // namespace organfit::phantom
