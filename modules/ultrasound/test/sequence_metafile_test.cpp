// Sequence metafiles: a written sweep reads back with its poses; malformed ones are
// refused naming the problem (cases found by fuzzing included).
#include "organfit/ultrasound/sequence_metafile.h"

#include <gtest/gtest.h>
#include <unistd.h>

#include <fstream>

#include "organfit/support/error.h"

namespace fs = std::filesystem;

namespace organfit::ultrasound {
namespace {

class SequenceFiles : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() / ("organfit_seq_" + std::to_string(getpid()));
    fs::create_directories(dir_);
  }
  void TearDown() override { fs::remove_all(dir_); }
  fs::path write(const std::string& name, const std::string& text) {
    std::ofstream(dir_ / name, std::ios::binary) << text;
    return dir_ / name;
  }
  std::string error_of(const fs::path& file) {
    try {
      const auto s = read_sequence_metafile(file);
      (void)assemble_sweep(s, nullptr, {});
    } catch (const InputError& e) {
      return e.what();
    }
    return "no error";
  }
  fs::path dir_;
};

TEST_F(SequenceFiles, AWrittenSweepReadsBackWithItsPoses) {
  TrackedSweep sweep;
  for (int f = 0; f < 3; ++f) {
    TrackedFrame frame;
    frame.index = f, frame.width = 4, frame.height = 3, frame.timestamp_s = 0.5 * f;
    frame.pixels.assign(12, static_cast<float>(10 * f));
    frame.pixel_to_ct_mm.setIdentity();
    frame.pixel_to_ct_mm.topLeftCorner<3, 2>() *=
        0.5;  // 0.5 mm pixels; the third column is the unit normal
    frame.pixel_to_ct_mm(2, 3) = 2.0 * f;
    sweep.frames.push_back(frame);
  }
  write_sequence_metafile(dir_ / "s.mha", sweep, 0.5);
  const SequenceMetafile s = read_sequence_metafile(dir_ / "s.mha");
  EXPECT_EQ(s.size, (std::array<int, 3>{4, 3, 3}));
  const TrackedSweep back = assemble_sweep(s, nullptr, {});
  ASSERT_EQ(back.frames.size(), 3u);
  EXPECT_EQ(back.frames[2].pixels[5], 20.0f);
  EXPECT_TRUE(back.frames[2].pixel_to_ct_mm.isApprox(sweep.frames[2].pixel_to_ct_mm, 1e-6));
}

TEST_F(SequenceFiles, MalformedFilesAreRefusedNamingTheProblem) {
  const std::string head =
      "ObjectType = Image\nNDims = 3\nDimSize = 2 2 1\nElementType = MET_UCHAR\n"
      "Seq_Frame0000_ProbeToTrackerTransform = 1 0 0 0 0 1 0 0 0 0 1 0 0 0 0 1\n";
  EXPECT_NE(error_of(write("nodata.mha", head)).find("no ElementDataFile line"), std::string::npos);
  // Found by fuzzing: a data file that is a folder threw std::ios_failure.
  EXPECT_NE(error_of(write("folder.mha", head + "ElementDataFile = .\n")).find("is missing"),
            std::string::npos);
  // Found by fuzzing: a DimSize of 7.8e42 overflowed the int it was cast to (UBSan).
  EXPECT_NE(
      error_of(write("huge.mha",
                     "DimSize = 7.8e42 2 1\nElementType = MET_UCHAR\nElementDataFile = LOCAL\n"))
          .find("DimSize must hold whole numbers"),
      std::string::npos);
  EXPECT_NE(
      error_of(write("short.mha", head + "ElementDataFile = LOCAL\nab")).find("DimSize needs 4"),
      std::string::npos);
  EXPECT_NE(error_of(write("type.mha",
                           "DimSize = 2 2 1\nElementType = MET_DOUBLE\nElementDataFile = LOCAL\n"))
                .find("not supported"),
            std::string::npos);
  const std::string scaled =
      "ObjectType = Image\nDimSize = 2 2 1\nElementType = MET_UCHAR\n"
      "Seq_Frame0000_ProbeToTrackerTransform = 2 0 0 0 0 1 0 0 0 0 1 0 0 0 0 1\nElementDataFile = "
      "LOCAL\nabcd";
  EXPECT_NE(error_of(write("scaled.mha", scaled)).find("is not a rigid transform"),
            std::string::npos);
}

}  // namespace
}  // namespace organfit::ultrasound
