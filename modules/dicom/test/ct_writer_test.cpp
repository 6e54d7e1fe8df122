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
  for (size_t v = 0; v < ct.hu.size(); ++v)
    ct.hu[v] = static_cast<float>(-1000.0 + 1.7 * static_cast<double>(v));
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
  for (size_t v = 1; v < ct.hu.size(); ++v)
    ASSERT_NEAR(back.hu[v], ct.hu[v], 0.5) << v;
  EXPECT_EQ(back.series_instance_uid, ct.series_instance_uid);
  EXPECT_EQ(back.frame_of_reference_uid, ct.frame_of_reference_uid);
  EXPECT_EQ(back.patient.study_instance_uid, ct.patient.study_instance_uid);
  for (size_t k = 0; k < ct.slices.size(); ++k)
    EXPECT_EQ(back.slices[k].sop_instance_uid, ct.slices[k].sop_instance_uid);
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

std::string read_error(const fs::path& folder) {
  try {
    read_ct_series(folder);
  } catch (const InputError& e) {
    return e.what();
  }
  return "no error";
}

// Defective series made with the writer, each refused by the reader naming the defect.
TEST_F(CtWriter, ATiltedSeriesIsRefused) {
  CtSeries ct = ramp_ct();
  const double t =
      10.0 * 3.14159265358979 / 180;  // slices shifted along y: a gantry tilt of 10 degrees
  ct.geometry.direction.col(2) = Eigen::Vector3d(0, std::sin(t), std::cos(t));
  write_ct_series(dir_ / "tilted", ct);
  EXPECT_NE(read_error(dir_ / "tilted").find("do not advance along the slice normal (gantry tilt"),
            std::string::npos)
      << read_error(dir_ / "tilted");
}

TEST_F(CtWriter, ANonAxialSeriesIsRefused) {
  CtSeries ct = ramp_ct();
  ct.geometry.direction << 1, 0, 0, 0, 0, 1, 0, -1, 0;  // coronal: rows along -z
  write_ct_series(dir_ / "coronal", ct);
  EXPECT_NE(read_error(dir_ / "coronal").find("non-axial slices"), std::string::npos)
      << read_error(dir_ / "coronal");
}

TEST_F(CtWriter, IrregularSliceSpacingIsRefused) {
  // Two writes with the same UIDs, the second shifted by 1 mm: one slice of it swapped
  // in gives gaps of 3.5 and 1.5 mm among 2.5 mm ones.
  CtWriteOptions fixed;
  fixed.fixed_uids_and_dates = true;
  CtSeries a = ramp_ct(), b = ramp_ct();
  b.geometry.origin_mm.z() += 1.0;
  write_ct_series(dir_ / "a", a, fixed);
  write_ct_series(dir_ / "b", b, fixed);
  fs::copy_file(dir_ / "b" / "CT0005.dcm", dir_ / "a" / "CT0005.dcm",
                fs::copy_options::overwrite_existing);
  EXPECT_NE(read_error(dir_ / "a").find("irregular slice spacing"), std::string::npos)
      << read_error(dir_ / "a");
}

}  // namespace
}  // namespace organfit::dicom
