#include "organfit/dicom/structure_set.h"

#include <gtest/gtest.h>
#include <sys/resource.h>
#include <unistd.h>

#include <cstdlib>
#include <fstream>
#include <map>

#include "organfit/support/error.h"

namespace fs = std::filesystem;

namespace organfit::dicom {
namespace {

fs::path data(const std::string& sub) {
  return fs::path(ORGANFIT_SHARED_DATA_DIR) / sub;
}

/// A small synthetic CT: 40 x 40 x 3 voxels of 1 mm, slices at z = 0, 2, 4 mm.
CtSeries small_ct() {
  CtSeries ct;
  ct.geometry.size = {40, 40, 3};
  ct.geometry.spacing_mm = {1, 1, 2};
  ct.frame_of_reference_uid = "1.2.3.4";
  for (int k = 0; k < 3; ++k)
    ct.slices.push_back({"1.2.3.4.5." + std::to_string(k), "", {0, 0, 2.0 * k}, {}});
  return ct;
}

Contour square(double x0, double y0, double side, double z, const std::string& uid = "") {
  return {"CLOSED_PLANAR",
          uid,
          {{x0, y0, z}, {x0 + side, y0, z}, {x0 + side, y0 + side, z}, {x0, y0 + side, z}}};
}

/// A structure set of one ROI "Organ" in the small CT's Frame of Reference.
StructureSet organ_of(std::vector<Contour> contours) {
  StructureSet s;
  Roi roi;
  roi.name = "Organ";
  roi.frame_of_reference_uid = "1.2.3.4";
  roi.contours = std::move(contours);
  s.rois.push_back(roi);
  return s;
}

std::string error_of(const StructureSet& s, const std::string& roi, const CtSeries& ct) {
  try {
    rasterise_roi(s, roi, ct, "rt.dcm");
  } catch (const InputError& e) {
    return e.what();
  }
  return "no error";
}

TEST(RasteriseRoi, EvenOddRuleMakesHolesAndIslands) {
  const CtSeries ct = small_ct();
  // On slice 1 (z = 2): a 30 mm square, a 20 mm hole in it, a 10 mm island in the hole.
  const StructureSet s =
      organ_of({square(4.5, 4.5, 30, 2, "1.2.3.4.5.1"), square(9.5, 9.5, 20, 2, "1.2.3.4.5.1"),
                square(14.5, 14.5, 10, 2)});  // the island references no slice: matched by z
  const RasterisedRoi r = rasterise_roi(s, "Organ", ct, "rt.dcm");
  EXPECT_EQ(r.mask.count(1), 30 * 30 - 20 * 20 + 10 * 10);
  EXPECT_EQ(r.mask.at(7, 7, 1), 1);    // in the square
  EXPECT_EQ(r.mask.at(12, 12, 1), 0);  // in the hole
  EXPECT_EQ(r.mask.at(20, 20, 1), 1);  // on the island
  EXPECT_EQ(r.mask.at(20, 20, 0), 0);  // other slices untouched
  EXPECT_EQ(r.matched_by_position, 1);
  ASSERT_EQ(r.warnings.size(), 1u);
  EXPECT_NE(r.warnings[0].find("1 of 3 contours"), std::string::npos);
}

TEST(RasteriseRoi, RefusesBadStructureSetsNamingTheProblem) {
  const CtSeries ct = small_ct();
  StructureSet s = organ_of({square(4.5, 4.5, 10, 2)});
  EXPECT_EQ(error_of(s, "Bladder", ct),
            "rt.dcm: no ROI named 'Bladder' (the structure set has 'Organ')");
  s.rois[0].frame_of_reference_uid = "9.9";
  EXPECT_NE(error_of(s, "Organ", ct).find("another Frame of Reference"), std::string::npos);
  s.rois[0].frame_of_reference_uid = "1.2.3.4";
  s.rois[0].contours = {{"OPEN_PLANAR", "", {{1, 1, 2}, {5, 1, 2}, {5, 5, 2}}}};
  EXPECT_EQ(error_of(s, "Organ", ct),
            "rt.dcm: ROI 'Organ' contour 1 is OPEN_PLANAR (a volume needs CLOSED_PLANAR contours)");
  s.rois[0].contours = {{"CLOSED_PLANAR", "", {{1, 1, 2}, {5, 1, 2}}}};
  EXPECT_EQ(error_of(s, "Organ", ct),
            "rt.dcm: ROI 'Organ' has no usable contour (1 skipped: fewer than 3 points or zero "
            "area)");
  s.rois[0].contours = {square(4.5, 4.5, 10, 2)};
  s.rois[0].contours[0].value_count = 11;
  s.rois[0].contours[0].declared_points = 4;
  EXPECT_EQ(error_of(s, "Organ", ct),
            "rt.dcm: ROI 'Organ' contour 1: its Contour Data has 11 values, not 3 x Number of "
            "Contour Points (4)");
  s.rois[0].contours = {square(100, 100, 10, 2)};
  EXPECT_EQ(error_of(s, "Organ", ct), "rt.dcm: ROI 'Organ' contour 1 lies outside the image");
  s.rois[0].contours = {square(4.5, 4.5, 10, 3.0)};  // between slices 1 and 2
  EXPECT_NE(error_of(s, "Organ", ct).find("lies on no slice"), std::string::npos);
}

TEST(RasteriseRoi, RefusesAStructureSetOfAnotherPatientStudyOrFrameNamingNoValue) {
  CtSeries ct = small_ct();
  ct.folder = "ctdir";
  ct.patient.patient_id = "PAT-001";
  ct.patient.study_instance_uid = "1.2.3.9";
  StructureSet s = organ_of({square(4.5, 4.5, 10, 2)});
  s.patient_id = "PAT-001";
  s.study_instance_uid = "1.2.3.9";
  EXPECT_EQ(error_of(s, "Organ", ct), "no error");
  s.patient_id = "PAT-002";
  EXPECT_EQ(error_of(s, "Organ", ct),
            "rt.dcm: its Patient ID differs from the CT's (ctdir): not a structure set of this CT");
  s.patient_id = "PAT-001";
  s.study_instance_uid = "1.2.3.8";
  EXPECT_EQ(error_of(s, "Organ", ct),
            "rt.dcm: its Study Instance UID differs from the CT's (ctdir): not a structure set of "
            "this CT");
  s.study_instance_uid = "1.2.3.9";
  // No Frame of Reference anywhere: only contours that reference the CT's slices place it.
  s.rois[0].frame_of_reference_uid.clear();
  EXPECT_NE(error_of(s, "Organ", ct).find("names no Frame of Reference"), std::string::npos);
  s.rois[0].contours = {square(4.5, 4.5, 10, 2, "1.2.3.4.5.1")};
  EXPECT_EQ(error_of(s, "Organ", ct), "no error");
  // The set's own Referenced Frame of Reference stands for an ROI that names none.
  s.referenced_frame_of_reference_uid = "7.7";
  EXPECT_NE(error_of(s, "Organ", ct).find("another Frame of Reference"), std::string::npos);
}

TEST(RasteriseRoi, TwoRoisOfOneNameNeedTheirNumber) {
  const CtSeries ct = small_ct();
  StructureSet s;
  for (int n : {3, 7}) {
    Roi roi;
    roi.number = n;
    roi.name = "GTV";
    roi.frame_of_reference_uid = "1.2.3.4";
    roi.contours = {square(4.5, 4.5, n == 3 ? 10 : 20, 2)};
    s.rois.push_back(roi);
  }
  EXPECT_EQ(error_of(s, "GTV", ct),
            "rt.dcm: 2 ROIs are named 'GTV' (ROI numbers 3, 7): choose one by its number "
            "(organ.roi_number, or segment --roi-number)");
  EXPECT_EQ(rasterise_roi(s, "GTV", ct, "rt.dcm", 7).mask.count(1), 20 * 20);
  EXPECT_EQ(rasterise_roi(s, "", ct, "rt.dcm", 3).mask.count(1), 10 * 10);
  EXPECT_THROW(rasterise_roi(s, "GTV", ct, "rt.dcm", 5), InputError);
}

TEST(RasteriseRoi, DegenerateContoursAreSkippedNamingTheirSlice) {
  const CtSeries ct = small_ct();
  StructureSet s = organ_of({square(4.5, 4.5, 10, 2, "1.2.3.4.5.1"),
                             {"CLOSED_PLANAR", "", {{1, 1, 4}, {5, 1, 4}}},
                             {"CLOSED_PLANAR", "", {{1, 1, 0}, {5, 1, 0}, {9, 1, 0}}}});
  const RasterisedRoi r = rasterise_roi(s, "Organ", ct, "rt.dcm");
  EXPECT_EQ(r.mask.count(1), 10 * 10);
  EXPECT_EQ(r.skipped, 2);
  ASSERT_EQ(r.warnings.size(), 2u);
  EXPECT_EQ(r.warnings[0],
            "rt.dcm: ROI 'Organ' contour 2 on slice 2 (z 4.00 mm) has 2 point(s), fewer than 3: "
            "skipped");
  EXPECT_EQ(r.warnings[1],
            "rt.dcm: ROI 'Organ' contour 3 on slice 0 (z 0.00 mm) has zero area: skipped");
}

TEST(RasteriseRoi, AReferenceItsPositionContradictsIsPlacedByPosition) {
  const CtSeries ct = small_ct();
  // References slice 0, lies on slice 2.
  StructureSet s = organ_of({square(4.5, 4.5, 10, 4, "1.2.3.4.5.0")});
  const RasterisedRoi r = rasterise_roi(s, "Organ", ct, "rt.dcm");
  EXPECT_EQ(r.mask.at(7, 7, 2), 1);
  EXPECT_EQ(r.mask.at(7, 7, 0), 0);
  EXPECT_EQ(r.matched_by_position, 1);
  s.rois[0].contours = {square(4.5, 4.5, 10, 3.0, "1.2.3.4.5.1")};  // half a gap off its slice
  EXPECT_NE(error_of(s, "Organ", ct).find("lies on no slice"), std::string::npos);
}

TEST(StructureSet, ImportsTheRealGtvDespiteMismatchedSliceReferences) {
  if (!fs::exists(data("ct-sts-002/rtstruct.dcm"))) GTEST_SKIP() << "real data absent";
  const CtSeries ct = read_ct_series(data("ct-sts-002/ct"));
  const StructureSet s = read_rtstruct(data("ct-sts-002/rtstruct.dcm"));
  ASSERT_EQ(s.rois.size(), 1u);
  EXPECT_EQ(s.rois[0].name, "GTV_Mass_CT");
  EXPECT_EQ(s.rois[0].contours.size(), 16u);
  EXPECT_EQ(s.frame_of_reference_uid, ct.frame_of_reference_uid);
  const RasterisedRoi r = rasterise_roi(s, "GTV_Mass_CT", ct, "rtstruct.dcm");
  EXPECT_EQ(r.matched_by_position, 16);  // the data's known quirk: references to uncropped slices
  EXPECT_EQ(r.warnings.size(), 1u);
  const double cm3 = r.mask.volume_mm3(1) / 1000.0;
  // 16 slices of 3.27 mm: a tumour of some tens of cm3 (printed for the record).
  std::cout << "GTV_Mass_CT (ct-sts-002): " << cm3 << " cm3\n";
  EXPECT_GT(cm3, 5.0);
  EXPECT_LT(cm3, 300.0);
}

TEST(StructureSet, AgreesWithPlastimatchRasterisationOnTheRealGtv) {
  if (!fs::exists(data("ct-sts-002/rtstruct.dcm"))) GTEST_SKIP() << "real data absent";
  if (std::system("command -v plastimatch > /dev/null 2>&1") != 0)
    GTEST_SKIP() << "plastimatch not installed";
  const fs::path dir =
      fs::temp_directory_path() / ("organfit_plastimatch_" + std::to_string(::getpid()));
  fs::create_directories(dir);
  const std::string cmd =
      "cd '" + dir.string() + "' && plastimatch convert --input '" +
      data("ct-sts-002/rtstruct.dcm").string() + "' --referenced-ct '" +
      data("ct-sts-002/ct").string() +
      "' --output-ss-img ss.nrrd > /dev/null 2>&1 && plastimatch stats ss.nrrd > stats.txt 2>&1";
  ASSERT_EQ(std::system(cmd.c_str()), 0);
  std::ifstream in(dir / "stats.txt");
  std::string line;
  long theirs = -1;
  while (std::getline(in, line))
    if (line.rfind("S    0  NVOX", 0) == 0) theirs = std::stol(line.substr(line.find("NVOX") + 4));
  fs::remove_all(dir);
  ASSERT_GT(theirs, 0);
  const CtSeries ct = read_ct_series(data("ct-sts-002/ct"));
  const long ours =
      rasterise_roi(read_rtstruct(data("ct-sts-002/rtstruct.dcm")), "GTV_Mass_CT", ct, "rt")
          .mask.count(1);
  EXPECT_NEAR(static_cast<double>(ours), static_cast<double>(theirs), 0.02 * theirs);
  std::cout << "GTV voxels: organfit " << ours << ", plastimatch " << theirs << "\n";
}

TEST(StructureSet, PlastimatchSynthFolderCtChosenByModalityRoisMatchPlastimatch) {
  // CT, RTSTRUCT and RTDOSE in one folder, written by plastimatch itself.
  if (std::system("command -v plastimatch > /dev/null 2>&1") != 0)
    GTEST_SKIP() << "plastimatch not installed";
  const fs::path dir =
      fs::temp_directory_path() / ("organfit_psynth_" + std::to_string(::getpid()));
  fs::remove_all(dir);
  fs::create_directories(dir);
  const std::string cmd =
      "cd '" + dir.string() +
      "' && plastimatch synth --pattern lung --dim '64 64 48' --spacing '3 3 3' --output-dicom dcm"
      " > /dev/null 2>&1 && plastimatch convert --input dcm/rtss_*.dcm --referenced-ct dcm"
      " --output-ss-img ss.nrrd > /dev/null 2>&1 && plastimatch stats ss.nrrd > stats.txt 2>&1";
  ASSERT_EQ(std::system(cmd.c_str()), 0);
  std::map<int, long> theirs;
  std::ifstream in(dir / "stats.txt");
  std::string line;
  while (std::getline(in, line))
    if (line.rfind("S ", 0) == 0)
      theirs[std::stoi(line.substr(2))] = std::stol(line.substr(line.find("NVOX") + 4));
  const CtSeries ct = read_ct_series(dir / "dcm");  // picked by modality among CT, RTSTRUCT, RTDOSE
  EXPECT_EQ(ct.geometry.size[2], 48);
  ASSERT_EQ(ct.warnings.size(), 1u);
  EXPECT_NE(ct.warnings[0].find("2 DICOM object(s) that are not CT"), std::string::npos);
  fs::path rt;
  for (const auto& e : fs::directory_iterator(dir / "dcm"))
    if (e.path().filename().string().rfind("rtss_", 0) == 0) rt = e.path();
  const StructureSet s = read_rtstruct(rt);
  const long body = rasterise_roi(s, "Body", ct, "rt").mask.count(1);
  const long lung = rasterise_roi(s, "Lung", ct, "rt").mask.count(1);
  fs::remove_all(dir);
  ASSERT_GT(theirs[0], 0);
  EXPECT_NEAR(static_cast<double>(body), static_cast<double>(theirs[0]), 0.02 * theirs[0]);
  EXPECT_NEAR(static_cast<double>(lung), static_cast<double>(theirs[1]), 0.02 * theirs[1]);
}

/// `bytes` written to a file of its own; the error read_rtstruct gives on it ("" if none).
std::string error_reading(const std::string& bytes) {
  const fs::path file = fs::path(::testing::TempDir()) / "raw_data_set.dcm";
  std::ofstream(file, std::ios::binary) << bytes;
  try {
    read_rtstruct(file);
  } catch (const InputError& e) {
    return e.what();
  }
  return "";
}

// A data set without preamble nor File Meta group is read in the encoding GDCM guesses from
// its first element, so it must be well formed in that one: a file well formed only in
// another was read as big endian by GDCM, a value's bytes taken as a length of 2.8 GB
// (fuzzing). Every one here is one element (0008,0060) Modality "RTSTRUCT", or a private
// element (0009,1001) LO "ABCD" before it.
TEST(StructureSet, ARawDataSetIsCheckedInTheEncodingGdcmReadsItIn) {
  using namespace std::string_literals;
  const std::string cannot = "cannot read as DICOM";
  const std::string modality_le = "\x08\x00\x60\x00"s + "CS\x08\x00"s + "RTSTRUCT";
  const std::string modality_implicit = "\x08\x00\x60\x00\x08\x00\x00\x00"s + "RTSTRUCT";
  const std::string private_le = "\x09\x00\x01\x10"s + "LO\x04\x00"s + "ABCD";
  const std::string private_be = "\x00\x09\x10\x01"s + "LO\x00\x04"s + "ABCD";
  const std::string modality_be = "\x00\x08\x00\x60"s + "CS\x00\x08"s + "RTSTRUCT";
  // Read (the structure set's other modules are missing: refused for that, not as unreadable).
  EXPECT_EQ(error_reading(modality_le).find(cannot), std::string::npos);
  EXPECT_EQ(error_reading(modality_implicit).find(cannot), std::string::npos);
  EXPECT_EQ(error_reading(private_be + modality_be).find(cannot), std::string::npos);
  // Element 0x1001 read little endian: GDCM takes big endian, where this is not well formed.
  EXPECT_NE(error_reading(private_le + modality_le).find(cannot), std::string::npos);
  // The fuzzer's case: a UC of 168 bytes, whose length read big endian is 0xa8000000 bytes.
  const long peak_kb = [] {
    rusage u{};
    getrusage(RUSAGE_SELF, &u);
    return u.ru_maxrss;
  }();
  EXPECT_NE(error_reading("\xff\x48\xd6\x22UC\x00\x00\xa8\x00\x00\x00"s + std::string(168, 'x'))
                .find(cannot),
            std::string::npos);
  rusage after{};
  getrusage(RUSAGE_SELF, &after);
  EXPECT_LT(after.ru_maxrss - peak_kb, 100 * 1024) << "kB more at its peak";
  // A first element GDCM finds no encoding for, and one it takes for implicit big endian.
  EXPECT_NE(error_reading("\x10\x00\x20\x00\x04\x00\x00\x00"s + "ABCD").find(cannot),
            std::string::npos);
  EXPECT_NE(error_reading("\x00\x08\x00\x60\x00\x00\x00\x08"s + "RTSTRUCT").find(cannot),
            std::string::npos);
}

TEST(StructureSet, ReadingSomethingElseIsRefused) {
  if (!fs::exists(data("ct-sts-002/ct/000000.dcm"))) GTEST_SKIP() << "real data absent";
  try {
    read_rtstruct(data("ct-sts-002/ct/000000.dcm"));
    FAIL();
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("not an RT Structure Set (Modality 'CT')"),
              std::string::npos);
  }
  EXPECT_THROW(read_rtstruct("/nonexistent.dcm"), InputError);
}

}  // namespace
}  // namespace organfit::dicom
