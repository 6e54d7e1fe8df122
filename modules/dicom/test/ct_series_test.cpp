// Reading real CT series (../shared/data) and refusing defective ones (made on copies).
#include "organfit/dicom/ct_series.h"

#include <gtest/gtest.h>
#include <unistd.h>

#include <algorithm>
#include <fstream>

#include "organfit/support/error.h"
#include "organfit/support/progress.h"

namespace fs = std::filesystem;

namespace organfit::dicom {
namespace {

fs::path data(const std::string& sub) {
  return fs::path(ORGANFIT_SHARED_DATA_DIR) / sub;
}

#define REQUIRE_DATA(sub) \
  if (!fs::exists(data(sub))) GTEST_SKIP() << "real data absent: " << data(sub).string()

std::string error_of(const fs::path& folder, const CtReadOptions& o = {}) {
  try {
    read_ct_series(folder, o);
  } catch (const InputError& e) {
    return e.what();
  }
  return "no error";
}

/// A scratch copy of some files of a series.
class Scratch {
 public:
  explicit Scratch(const std::string& name)
      : dir_(fs::temp_directory_path() / ("organfit_ct_" + name + "_" + std::to_string(getpid()))) {
    fs::remove_all(dir_);
    fs::create_directories(dir_);
  }
  ~Scratch() { fs::remove_all(dir_); }
  void copy_series(const fs::path& from, const std::string& prefix = "", int skip = -1) {
    std::vector<fs::path> files;
    for (const auto& e : fs::directory_iterator(from))
      files.push_back(e.path());
    std::sort(files.begin(), files.end());
    for (size_t i = 0; i < files.size(); ++i)
      if (static_cast<int>(i) != skip)
        fs::copy_file(files[i], dir_ / (prefix + files[i].filename().string()));
  }
  const fs::path& dir() const { return dir_; }

 private:
  fs::path dir_;
};

TEST(CtSeries, ReadsStsCt002WithItsGeometryAndSliceUids) {
  REQUIRE_DATA("ct-sts-002/ct");
  // Progress by slice, as a log shows it when every update is drawn (a CT of a thousand
  // thin slices takes seconds).
  Progress::set_force_plain(true);
  Progress::set_plain_interval_s(0);
  ::testing::internal::CaptureStderr();
  const CtSeries ct = read_ct_series(data("ct-sts-002/ct"));
  const std::string err = ::testing::internal::GetCapturedStderr();
  Progress::set_force_plain(false);
  Progress::set_plain_interval_s(5.0);
  EXPECT_NE(err.find("ct: reading pixels: 50% (24/48)"), std::string::npos) << err;
  EXPECT_NE(err.find("ct: reading pixels: 100% (48/48)"), std::string::npos) << err;
  EXPECT_EQ(ct.geometry.size[0], 161);  // columns
  EXPECT_EQ(ct.geometry.size[1], 143);  // rows
  EXPECT_EQ(ct.geometry.size[2], 48);
  EXPECT_NEAR(ct.geometry.spacing_mm.x(), 0.976562, 1e-6);
  EXPECT_NEAR(ct.geometry.spacing_mm.z(), 3.27, 1e-3);
  EXPECT_TRUE(ct.geometry.direction.isIdentity(1e-9));
  EXPECT_EQ(ct.frame_of_reference_uid,
            "1.3.6.1.4.1.14519.5.2.1.5168.1900.114679355310645018817373178374");
  ASSERT_EQ(ct.slices.size(), 48u);
  for (size_t s = 1; s < ct.slices.size(); ++s) {
    EXPECT_NEAR(ct.slices[s].position_mm.z() - ct.slices[s - 1].position_mm.z(), 3.27, 1e-3);
    EXPECT_FALSE(ct.slices[s].sop_instance_uid.empty());
  }
  EXPECT_EQ(ct.geometry.origin_mm, ct.slices.front().position_mm);
  // Hounsfield units: air, soft tissue and bone are all present in a plausible range.
  const auto [lo, hi] = std::minmax_element(ct.hu.begin(), ct.hu.end());
  EXPECT_GE(*lo, -1100.f);
  EXPECT_LE(*hi, 4000.f);
  const long soft =
      std::count_if(ct.hu.begin(), ct.hu.end(), [](float v) { return v > -100 && v < 100; });
  EXPECT_GT(soft, static_cast<long>(ct.hu.size() / 4));
  EXPECT_FALSE(ct.patient.study_instance_uid.empty());
}

TEST(CtSeries, ReadsStsCt004AndTheAbdominalCtWithItsRescale) {
  REQUIRE_DATA("ct-sts-004/ct");
  REQUIRE_DATA("ct-crlm-1004/ct");
  const CtSeries sts = read_ct_series(data("ct-sts-004/ct"));
  EXPECT_EQ(sts.geometry.size[2], 85);
  const CtSeries abd = read_ct_series(data("ct-crlm-1004/ct"));
  EXPECT_EQ(abd.geometry.size[0], 512);
  EXPECT_EQ(abd.geometry.size[1], 512);
  EXPECT_EQ(abd.geometry.size[2], 41);
  EXPECT_NEAR(abd.geometry.spacing_mm.z(), 5.0, 1e-3);
  // Rescale intercept -1024: air outside the body reads about -1000 HU.
  const long air = std::count_if(abd.hu.begin(), abd.hu.end(), [](float v) { return v < -900; });
  EXPECT_GT(air, static_cast<long>(abd.hu.size() / 10));
}

TEST(CtSeries, StrayFilesAndOtherModalitiesAreToleratedWithAWarning) {
  REQUIRE_DATA("ct-sts-002");
  Scratch s("stray");
  s.copy_series(data("ct-sts-002/ct"));
  fs::copy_file(data("ct-sts-002/rtstruct.dcm"), s.dir() / "rtstruct.dcm");
  std::ofstream(s.dir() / "README.txt") << "not DICOM\n";
  const CtSeries ct = read_ct_series(s.dir());
  EXPECT_EQ(ct.geometry.size[2], 48);
  ASSERT_EQ(ct.warnings.size(), 2u);
  EXPECT_NE(ct.warnings[0].find("1 file(s) that are not DICOM"), std::string::npos);
  EXPECT_NE(ct.warnings[1].find("not CT"), std::string::npos);
}

TEST(CtSeries, MissingSliceIsRefusedNamingTheGap) {
  REQUIRE_DATA("ct-sts-002/ct");
  Scratch s("missing");
  s.copy_series(data("ct-sts-002/ct"), "", 20);
  const std::string e = error_of(s.dir());
  EXPECT_NE(e.find("missing slice: a gap of 6.54 mm"), std::string::npos) << e;
  EXPECT_EQ(e.find(s.dir().string() + ": "), 0u) << e;
}

TEST(CtSeries, TwoFilesOfOneSopInstanceAreRefused) {
  REQUIRE_DATA("ct-sts-002/ct");
  Scratch s("duplicate");
  s.copy_series(data("ct-sts-002/ct"));
  fs::copy_file(data("ct-sts-002/ct/000010.dcm"), s.dir() / "copy_of_10.dcm");
  const std::string e = error_of(s.dir());
  EXPECT_NE(e.find(": 000010.dcm and copy_of_10.dcm have the same SOP Instance UID"),
            std::string::npos)
      << e;
}

TEST(CtSeries, TwoSeriesNeedAChoiceAndTheChoiceWorks) {
  REQUIRE_DATA("ct-sts-002/ct");
  REQUIRE_DATA("ct-sts-004/ct");
  Scratch s("two");
  s.copy_series(data("ct-sts-002/ct"), "a_");
  s.copy_series(data("ct-sts-004/ct"), "b_");
  const std::string e = error_of(s.dir());
  EXPECT_NE(e.find("2 CT series; choose one"), std::string::npos) << e;
  const CtSeries only = read_ct_series(data("ct-sts-004/ct"));
  CtReadOptions o;
  o.series_instance_uid = only.series_instance_uid;
  EXPECT_EQ(read_ct_series(s.dir(), o).geometry.size[2], 85);
  o.series_instance_uid = "1.2.3";
  EXPECT_NE(error_of(s.dir(), o).find("no CT series with UID 1.2.3"), std::string::npos);
}

TEST(CtSeries, EmptyFolderAndNotAFolderAreRefused) {
  Scratch s("empty");
  EXPECT_EQ(error_of(s.dir()), s.dir().string() + ": the folder is empty: no CT series");
  EXPECT_EQ(error_of("/nonexistent/ct"), "/nonexistent/ct: not a folder");
  std::ofstream(s.dir() / "notes.txt") << "x";
  EXPECT_EQ(error_of(s.dir()),
            s.dir().string() + ": no CT series (no DICOM file with Modality CT)");
}

}  // namespace
}  // namespace organfit::dicom
