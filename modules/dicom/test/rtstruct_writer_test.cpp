// DICOM round trips of the RT Structure Set we write: our reader, plastimatch, pydicom.
#include "organfit/dicom/rtstruct_writer.h"

#include <gtest/gtest.h>
#include <unistd.h>

#include <cstdlib>
#include <fstream>

#include "organfit/dicom/structure_set.h"
#include "organfit/geometry/mask_ops.h"
#include "organfit/itkbridge/itk_images.h"
#include "organfit/support/error.h"

namespace fs = std::filesystem;

namespace organfit::dicom {
namespace {

fs::path data(const std::string& sub) {
  return fs::path(ORGANFIT_SHARED_DATA_DIR) / sub;
}

class RtstructRoundTrip : public ::testing::Test {
 protected:
  void SetUp() override {
    if (!fs::exists(data("ct-sts-002/rtstruct.dcm"))) GTEST_SKIP() << "real data absent";
    ct_ = read_ct_series(data("ct-sts-002/ct"));
    mask_ = rasterise_roi(read_rtstruct(data("ct-sts-002/rtstruct.dcm")), "GTV_Mass_CT", ct_, "rt")
                .mask;
    dir_ = fs::temp_directory_path() / ("organfit_rtss_" + std::to_string(getpid()));
    fs::remove_all(dir_);
    fs::create_directories(dir_);
    out_ = dir_ / "fit.dcm";
    RtstructRoi roi{"GTV_fit", {0, 200, 255}, geometry::slice_contours(mask_, 1)};
    RtstructWriteOptions o;
    o.fixed_uids_and_dates = true;
    write_rtstruct(out_, ct_, {roi}, o);
  }
  void TearDown() override { fs::remove_all(dir_); }
  CtSeries ct_;
  geometry::LabelVolume mask_;
  fs::path dir_, out_;
};

TEST_F(RtstructRoundTrip, OurReaderGetsTheSameVoxelsBackWithMatchingSliceReferences) {
  const StructureSet back = read_rtstruct(out_);
  ASSERT_EQ(back.rois.size(), 1u);
  EXPECT_EQ(back.rois[0].name, "GTV_fit");
  EXPECT_EQ(back.frame_of_reference_uid, ct_.frame_of_reference_uid);
  const RasterisedRoi r = rasterise_roi(back, "GTV_fit", ct_, out_.string());
  EXPECT_EQ(r.matched_by_position, 0);  // every contour references a slice of this CT
  geometry::LabelVolume again = r.mask;
  const auto cmp = geometry::compare_masks(again, mask_);
  EXPECT_GE(cmp.dice, 0.98);
  EXPECT_EQ(again.labels, mask_.labels);  // marching squares + even-odd: exact
}

TEST_F(RtstructRoundTrip, PlastimatchRasterisesItToTheSameMask) {
  if (std::system("command -v plastimatch > /dev/null 2>&1") != 0)
    GTEST_SKIP() << "plastimatch not installed";
  // plastimatch writes one mask per ROI on the referenced CT's grid; compared voxel by
  // voxel (through physical positions, so a grid convention difference would show).
  const std::string cmd = "cd '" + dir_.string() +
                          "' && plastimatch convert --input fit.dcm --referenced-ct '" +
                          data("ct-sts-002/ct").string() + "' --output-prefix pm > pm.log 2>&1";
  ASSERT_EQ(std::system(cmd.c_str()), 0);
  ASSERT_TRUE(fs::exists(dir_ / "pm" / "GTV_fit.mha")) << "no GTV_fit.mha from plastimatch";
  const geometry::LabelVolume theirs = itkbridge::read_label_volume(dir_ / "pm" / "GTV_fit.mha");
  const auto& g = mask_.geometry;
  long long both = 0, ours = 0, their_count = 0;
  for (int k = 0; k < g.size[2]; ++k)
    for (int j = 0; j < g.size[1]; ++j)
      for (int i = 0; i < g.size[0]; ++i) {
        const bool a = mask_.at(i, j, k) == 1;
        const bool b = theirs.at_physical(g.index_to_physical(Eigen::Vector3d(i, j, k))) != 0;
        ours += a, their_count += b, both += a && b;
      }
  ASSERT_GT(ours, 1000);
  const double dice = 2.0 * static_cast<double>(both) / static_cast<double>(ours + their_count);
  EXPECT_GE(dice, 0.97) << "ours " << ours << ", plastimatch " << their_count;
  RecordProperty("dice_vs_plastimatch", std::to_string(dice));
}

TEST_F(RtstructRoundTrip, PydicomReadsItAndEveryContourReferencesACtSlice) {
  if (std::system("/usr/bin/python3 -c 'import pydicom' > /dev/null 2>&1") != 0)
    GTEST_SKIP() << "pydicom not installed";
  std::ofstream uids(dir_ / "uids.txt");
  for (const auto& s : ct_.slices)
    uids << s.sop_instance_uid << "\n";
  uids.close();
  const std::string script =
      "import pydicom, sys\n"
      "ds = pydicom.dcmread(sys.argv[1])\n"
      "uids = set(open(sys.argv[2]).read().split())\n"
      "assert ds.Modality == 'RTSTRUCT' and ds.file_meta.TransferSyntaxUID == "
      "'1.2.840.10008.1.2.1'\n"
      "refs = [c.ContourImageSequence[0].ReferencedSOPInstanceUID for r in ds.ROIContourSequence "
      "for c in r.ContourSequence]\n"
      "assert refs and all(u in uids for u in refs), 'a contour references no CT slice'\n"
      "assert ds.StructureSetROISequence[0].ROIGenerationAlgorithm == 'AUTOMATIC'\n";
  std::ofstream(dir_ / "check.py") << script;
  EXPECT_EQ(std::system(("/usr/bin/python3 '" + (dir_ / "check.py").string() + "' '" +
                         out_.string() + "' '" + (dir_ / "uids.txt").string() + "'")
                            .c_str()),
            0);
}

/// Error lines of a dicom3tools command (without its closing summary line).
std::vector<std::string> errors_of(const std::string& command, const fs::path& log) {
  std::system((command + " > '" + log.string() + "' 2>&1").c_str());
  std::vector<std::string> out;
  std::ifstream in(log);
  std::string line;
  while (std::getline(in, line))
    if (line.rfind("Error", 0) == 0 &&
        line.find("contains invalid data values") == std::string::npos)
      out.push_back(line);
  return out;
}

TEST_F(RtstructRoundTrip, Dicom3toolsFindNoErrorOfOursAndNoInconsistencyWithTheCt) {
  if (std::system("command -v dciodvfy > /dev/null 2>&1") != 0)
    GTEST_SKIP() << "dicom3tools not installed";
  // dciodvfy: every error in our file must already be in the CT it copies from (this
  // CT's Study ID has 17 characters, one more than SH allows; it is copied verbatim).
  const auto ours = errors_of("dciodvfy '" + out_.string() + "'", dir_ / "ours.txt");
  const auto source = errors_of("dciodvfy '" + ct_.slices[0].file.string() + "'", dir_ / "ct.txt");
  for (const auto& e : ours) {
    const std::string attribute = e.substr(0, e.find(" - Length"));
    bool inherited = false;
    for (const auto& c : source)
      inherited = inherited || c.find(attribute.substr(attribute.find('('))) != std::string::npos;
    EXPECT_TRUE(inherited) << "our error: " << e;
  }
  // dcentvfy on the CT and the structure set together: consistent.
  std::string files;
  for (const auto& slice : ct_.slices)
    files += "'" + slice.file.string() + "' ";
  EXPECT_TRUE(errors_of("dcentvfy " + files + "'" + out_.string() + "'", dir_ / "ent.txt").empty());
}

TEST(SliceContours, ThinningKeepsContourDataUnderTheDicomLimit) {
  geometry::ImageGeometry g;
  g.size = {400, 400, 1};
  g.spacing_mm = {0.5, 0.5, 1};
  geometry::LabelVolume disc(g);
  for (int j = 0; j < 400; ++j)
    for (int i = 0; i < 400; ++i)
      disc.at(i, j, 0) = std::hypot(i - 200.0, j - 200.0) < 190;
  const auto exact = geometry::slice_contours(disc, 1, 100000);
  const auto thin = geometry::slice_contours(disc, 1, 500);
  ASSERT_EQ(exact.size(), 1u);
  ASSERT_EQ(thin.size(), 1u);
  EXPECT_GT(exact[0].points_mm.size(), 500u);
  EXPECT_LE(thin[0].points_mm.size(), 500u);
  EXPECT_GT(thin[0].thinning_tolerance_mm, 0.0);
  EXPECT_LT(thin[0].thinning_tolerance_mm, 0.5);  // well under a voxel
}

}  // namespace
}  // namespace organfit::dicom
