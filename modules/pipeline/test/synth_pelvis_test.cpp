// The pelvis phantom as written to disk: read back by the CT stage, its Prostate
// imported from its RT Structure Set and grown from a seed, against the true labels.
#include <gtest/gtest.h>
#include <unistd.h>

#include <fstream>
#include <iterator>

#include "organfit/dicom/structure_set.h"
#include "organfit/geometry/mask_ops.h"
#include "organfit/itkbridge/itk_images.h"
#include "organfit/pipeline/phantom_stage.h"
#include "organfit/segmentation/segment.h"
#include "organfit/support/error.h"

namespace fs = std::filesystem;

namespace organfit::pipeline {
namespace {

fs::path scratch(const std::string& name) {
  return fs::temp_directory_path() / ("organfit_synth_" + name + "_" + std::to_string(getpid()));
}

geometry::LabelVolume only(const geometry::LabelVolume& labels, std::uint8_t label) {
  geometry::LabelVolume m(labels.geometry);
  for (size_t v = 0; v < m.labels.size(); ++v)
    m.labels[v] = labels.labels[v] == label ? 1 : 0;
  return m;
}

class PelvisOnDisk : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    dir_ = scratch("default");
    fs::remove_all(dir_);
    result_ = write_pelvis_phantom(dir_, phantom::PelvisOptions{});
    ct_ = dicom::read_ct_series(dir_ / "ct");
    truth_ = itkbridge::read_label_volume(dir_ / "labels.nrrd");
  }
  static void TearDownTestSuite() { fs::remove_all(dir_); }
  static fs::path dir_;
  static SynthResult result_;
  static dicom::CtSeries ct_;
  static geometry::LabelVolume truth_;
};
fs::path PelvisOnDisk::dir_;
SynthResult PelvisOnDisk::result_;
dicom::CtSeries PelvisOnDisk::ct_;
geometry::LabelVolume PelvisOnDisk::truth_;

TEST_F(PelvisOnDisk, CtReadsBackOnTheLabelsGridWithTheProstateAt35Cm3) {
  EXPECT_NEAR(result_.prostate_volume_cm3, 35.0, 1.0);
  EXPECT_EQ(ct_.geometry.size, truth_.geometry.size);
  EXPECT_TRUE(ct_.geometry.origin_mm.isApprox(truth_.geometry.origin_mm, 1e-6));
  EXPECT_TRUE(ct_.geometry.spacing_mm.isApprox(truth_.geometry.spacing_mm, 1e-9));
  EXPECT_EQ(truth_.at_physical(Eigen::Vector3d(0, 0, 0)), phantom::kProstate);
  // Mean HU of the prostate's interior voxels (no partial volume): 42 HU; boundary
  // voxels are pulled towards their neighbours' values.
  double sum = 0;
  long n = 0;
  const auto& g = truth_.geometry;
  for (int k = 1; k + 1 < g.size[2]; ++k)
    for (int j = 1; j + 1 < g.size[1]; ++j)
      for (int i = 1; i + 1 < g.size[0]; ++i) {
        bool interior = truth_.at(i, j, k) == phantom::kProstate;
        for (int d = -1; d <= 1; d += 2)
          interior = interior && truth_.at(i + d, j, k) == phantom::kProstate &&
                     truth_.at(i, j + d, k) == phantom::kProstate &&
                     truth_.at(i, j, k + d) == phantom::kProstate;
        if (interior) sum += ct_.hu[static_cast<size_t>(g.linear_index(i, j, k))], ++n;
      }
  ASSERT_GT(n, 3000);
  EXPECT_NEAR(sum / n, 42.0, 1.0);
}

TEST_F(PelvisOnDisk, RtstructImportOfTheProstateMatchesTheTrueLabel) {
  const auto rtss = dicom::read_rtstruct(dir_ / "rtstruct.dcm");
  for (const auto& s : phantom::pelvis_structures())
    EXPECT_NE(rtss.find(s.name), nullptr) << s.name;
  const auto roi = dicom::rasterise_roi(rtss, "Prostate", ct_, "rtstruct.dcm");
  EXPECT_EQ(roi.matched_by_position, 0);
  const auto cmp = geometry::compare_masks(roi.mask, only(truth_, phantom::kProstate));
  EXPECT_GE(cmp.dice, 0.98);
  const auto bladder = dicom::rasterise_roi(rtss, "Bladder", ct_, "rtstruct.dcm");
  EXPECT_GE(geometry::compare_masks(bladder.mask, only(truth_, phantom::kBladder)).dice, 0.98);
}

TEST_F(PelvisOnDisk, SeededSegmentationOfTheProstateReachesDice090) {
  segmentation::SeedOptions s;
  s.seed_mm = Eigen::Vector3d(0, 0, 0);
  s.hu_low = 20;  // between urine (12) and prostate (42), the low-contrast side
  s.hu_high = 80;
  const auto mask = segmentation::segment_from_seed(ct_.geometry, ct_.hu, s).mask;
  const auto cmp = geometry::compare_masks(mask, only(truth_, phantom::kProstate));
  EXPECT_GE(cmp.dice, 0.90);
  EXPECT_NEAR(cmp.volume_a_mm3 / cmp.volume_b_mm3, 1.0, 0.15);
}

std::string bytes(const fs::path& f) {
  std::ifstream in(f, std::ios::binary);
  return {std::istreambuf_iterator<char>(in), {}};
}

TEST(SynthPelvis, SameSeedSameBytesOtherSeedOtherNoise) {
  phantom::PelvisOptions o;
  o.columns = o.rows = 80, o.pixel_mm = 5, o.slices = 12, o.slice_mm = 10;
  const fs::path a = scratch("a"), b = scratch("b"), c = scratch("c");
  for (const auto& d : {a, b, c})
    fs::remove_all(d);
  write_pelvis_phantom(a, o);
  write_pelvis_phantom(b, o);
  o.seed = 2;
  write_pelvis_phantom(c, o);
  for (const char* f : {"ct/CT0006.dcm", "rtstruct.dcm", "labels.nrrd", "phantom.json"})
    EXPECT_EQ(bytes(a / f), bytes(b / f)) << f;
  EXPECT_NE(bytes(a / "ct/CT0006.dcm"), bytes(c / "ct/CT0006.dcm"));
  EXPECT_THROW(write_pelvis_phantom(a, o), InputError);  // not an empty folder
  for (const auto& d : {a, b, c})
    fs::remove_all(d);
}

}  // namespace
}  // namespace organfit::pipeline
