// Writing a CT series and reading it back: geometry, HU and UIDs survive.
#include "organfit/dicom/ct_writer.h"

#include <gtest/gtest.h>
#include <unistd.h>

#include <cmath>

#include "organfit/support/error.h"

namespace fs = std::filesystem;

namespace organfit::dicom {
namespace {

CtSeries ramp_ct() {
  CtSeries ct;
  ct.geometry.size = {12, 10, 9};
  ct.geometry.spacing_mm = Eigen::Vector3d(0.8, 0.8, 2.5);
  ct.geometry.origin_mm = Eigen::Vector3d(-4.4, 7.2, -30);
  ct.hu.resize(static_cast<size_t>(ct.geometry.voxel_count()));
  for (size_t v = 0; v < ct.hu.size(); ++v) ct.hu[v] = static_cast<float>(-1000.0 + 1.7 * static_cast<double>(v));
  ct.hu[0] = -2000;  // below the 12-bit range: clipped and counted
  ct.patient.patient_name = "Test^Ramp";
  ct.patient.patient_id = "RAMP";
  ct.series_description = "ramp";
  return ct;
}

class CtWriter : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() / ("organfit_ctw_" + std::to_string(getpid()));
    fs::remove_all(dir_);
  }
  void TearDown() override { fs::remove_all(dir_); }
  fs::path dir_;
};

TEST_F(CtWriter, RoundTripKeepsGeometryHuAndSliceUids) {
  CtSeries ct = ramp_ct();
  EXPECT_EQ(write_ct_series(dir_ / "ct", ct), 1);
  ASSERT_EQ(ct.slices.size(), 9u);
  const CtSeries back = read_ct_series(dir_ / "ct");
  EXPECT_EQ(back.geometry.size, ct.geometry.size);
  EXPECT_TRUE(back.geometry.spacing_mm.isApprox(ct.geometry.spacing_mm, 1e-9));
  EXPECT_TRUE(back.geometry.origin_mm.isApprox(ct.geometry.origin_mm, 1e-9));
  EXPECT_TRUE(back.geometry.direction.isApprox(Eigen::Matrix3d::Identity()));
  ASSERT_EQ(back.hu.size(), ct.hu.size());
  EXPECT_EQ(back.hu[0], -1024.0f);
  for (size_t v = 1; v < ct.hu.size(); ++v) ASSERT_NEAR(back.hu[v], ct.hu[v], 0.5) << v;
  EXPECT_EQ(back.series_instance_uid, ct.series_instance_uid);
  EXPECT_EQ(back.frame_of_reference_uid, ct.frame_of_reference_uid);
  EXPECT_EQ(back.patient.study_instance_uid, ct.patient.study_instance_uid);
  for (size_t k = 0; k < ct.slices.size(); ++k) EXPECT_EQ(back.slices[k].sop_instance_uid, ct.slices[k].sop_instance_uid);
}

TEST_F(CtWriter, FixedUidsGiveTheSameUidsAndNewOnesDiffer) {
  CtWriteOptions fixed;
  fixed.fixed_uids_and_dates = true;
  CtSeries a = ramp_ct(), b = ramp_ct(), c = ramp_ct();
  write_ct_series(dir_ / "a", a, fixed);
  write_ct_series(dir_ / "b", b, fixed);
  write_ct_series(dir_ / "c", c);
  EXPECT_EQ(a.series_instance_uid, b.series_instance_uid);
  EXPECT_EQ(a.slices[3].sop_instance_uid, b.slices[3].sop_instance_uid);
  EXPECT_NE(a.series_instance_uid, c.series_instance_uid);
  EXPECT_NE(a.slices[3].sop_instance_uid, a.slices[4].sop_instance_uid);
}

TEST_F(CtWriter, RefusesAnExistingFolderAndWritesNothingOnBadInput) {
  CtSeries ct = ramp_ct();
  fs::create_directories(dir_ / "ct");
  EXPECT_THROW(write_ct_series(dir_ / "ct", ct), InputError);
  ct.hu.pop_back();
  EXPECT_THROW(write_ct_series(dir_ / "other", ct), InputError);
  EXPECT_FALSE(fs::exists(dir_ / "other"));
}

}  // namespace
}  // namespace organfit::dicom
