#include "organfit/segmentation/segment.h"

#include <gtest/gtest.h>

#include "organfit/dicom/structure_set.h"
#include "organfit/support/error.h"
#include "organfit/support/progress.h"

namespace fs = std::filesystem;

namespace organfit::segmentation {
namespace {

fs::path data(const std::string& sub) {
  return fs::path(ORGANFIT_SHARED_DATA_DIR) / sub;
}

TEST(SegmentFromSeed, SphereInNoiseIsRecoveredWhole) {
  geometry::ImageGeometry g;
  g.size = {40, 40, 20};
  g.spacing_mm = {1, 1, 2};
  std::vector<float> hu(g.voxel_count());
  unsigned state = 7;
  auto noise = [&] {
    state = state * 1103515245u + 12345u;
    return static_cast<float>((state >> 16) % 41) - 20.f;
  };
  long inside = 0;
  for (int k = 0; k < 20; ++k)
    for (int j = 0; j < 40; ++j)
      for (int i = 0; i < 40; ++i) {
        const bool in = Eigen::Vector3d(i - 20, j - 20, 2.0 * (k - 10)).norm() < 12;
        inside += in;
        hu[g.linear_index(i, j, k)] = (in ? 60.f : -80.f) + noise();
      }
  SeedOptions o;
  o.seed_mm = {20, 20, 20};
  o.hu_low = 20;
  o.hu_high = 100;
  // Progress lines as a log shows them (every update drawn): each filter's, the
  // smoothing's first, and a done line.
  Progress::set_force_plain(true);
  Progress::set_plain_interval_s(0);
  ::testing::internal::CaptureStderr();
  const geometry::LabelVolume m = segment_from_seed(g, hu, o).mask;
  const std::string err = ::testing::internal::GetCapturedStderr();
  Progress::set_force_plain(false);
  Progress::set_plain_interval_s(5.0);
  EXPECT_NE(err.find("segment: "), std::string::npos) << err;
  EXPECT_LT(err.find("smoothing"), err.find("filling its holes")) << err;
  EXPECT_NE(err.find("segment: 100% (700/700)"), std::string::npos) << err;
  EXPECT_NEAR(static_cast<double>(m.count(1)), static_cast<double>(inside), 0.05 * inside);
  EXPECT_EQ(m.at(20, 20, 10), 1);
  EXPECT_EQ(m.at(2, 2, 2), 0);
}

TEST(SegmentFromSeed, BadSeedsAreRefusedNamingTheProblem) {
  geometry::ImageGeometry g;
  g.size = {10, 10, 10};
  std::vector<float> hu(g.voxel_count(), 0.f);
  SeedOptions o;
  o.seed_mm = {50, 5, 5};
  o.hu_low = -10;
  o.hu_high = 10;
  EXPECT_THROW(segment_from_seed(g, hu, o), InputError);
  o.seed_mm = {5, 5, 5};
  o.hu_low = 100;
  o.hu_high = 200;
  try {
    segment_from_seed(g, hu, o);
    FAIL();
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find(
                  "reads 0 HU at the seed (5.0, 5.0, 5.0) mm, outside the window [100, 200]"),
              std::string::npos)
        << e.what();
  }
}

TEST(SegmentFromSeed, LiverOfTheRealAbdominalCtHasAPlausibleVolume) {
  if (!fs::exists(data("ct-crlm-1004/ct"))) GTEST_SKIP() << "real data absent";
  const dicom::CtSeries ct = dicom::read_ct_series(data("ct-crlm-1004/ct"));
  SeedOptions o;
  o.seed_mm = {-78.7, -4.8, -250.0};  // in the liver on slice 25 (portal venous phase)
  o.hu_low = 95;                      // the liver reads 120 +- 11 HU around the seed
  o.hu_high = 150;
  o.opening_radius_voxels = 2;  // radius 1 still leaks into stomach contents
  o.search_box_mm = 0;          // the whole CT: a liver is wider than the default box
  const geometry::LabelVolume liver = segment_from_seed(ct.geometry, ct.hu, o).mask;
  const double cm3 = liver.volume_mm3(1) / 1000.0;
  std::cout << "liver (ct-crlm-1004, from a seed): " << cm3 << " cm3\n";
  EXPECT_GT(cm3, 800.0);   // an adult liver holds about 1.2 to 1.8 litres;
  EXPECT_LT(cm3, 2500.0);  // the scan covers 20 cm of it
  // In the default 200 mm box the liver reaches the box's edge, and the result says so.
  o.search_box_mm = 200;
  const SeededOrgan boxed = segment_from_seed(ct.geometry, ct.hu, o);
  ASSERT_EQ(boxed.warnings.size(), 1u);
  EXPECT_NE(boxed.warnings[0].find("reaches the edge of the 200 mm search box"), std::string::npos);
  EXPECT_LT(boxed.mask.count(1), liver.count(1));
}

}  // namespace
}  // namespace organfit::segmentation
