#include "organfit/pipeline/points_file.h"

#include <gtest/gtest.h>
#include <unistd.h>

#include <fstream>

#include "organfit/pipeline/points_stage.h"
#include "organfit/support/error.h"

namespace fs = std::filesystem;

namespace organfit::pipeline {
namespace {

class PointsFile : public ::testing::Test {
 protected:
  fs::path write(const std::string& bytes) {
    const fs::path p =
        fs::temp_directory_path() /
        ("organfit_points_" + std::to_string(::getpid()) + "_" + std::to_string(count_++) + ".csv");
    std::ofstream(p, std::ios::binary) << bytes;
    files_.push_back(p);
    return p;
  }
  static std::string utf16le(const std::string& ascii, bool mark) {
    std::string out = mark ? std::string("\xFF\xFE", 2) : std::string();
    for (char c : ascii)
      out += c, out += '\0';
    return out;
  }
  std::string error_of(const std::string& bytes) {
    try {
      (void)read_points_csv(write(bytes));
    } catch (const InputError& e) {
      const std::string m = e.what();
      return m.substr(m.find(".csv") + 4);
    }
    return "no error";
  }
  void TearDown() override {
    for (const auto& f : files_)
      fs::remove(f);
  }
  std::vector<fs::path> files_;
  int count_ = 0;
};

// Every way a spreadsheet or a script writes the same two points gives the same numbers.
TEST_F(PointsFile, ReadsTheSamePointsFromEveryEncodingAndSeparator) {
  const std::vector<std::string> forms = {
      "x,y,z,confidence\n1.5,-2,3,0.5\n4,5.25,6e1,1\n",
      "\xEF\xBB\xBFx,y,z,c\r\n1.5,-2,3,0.5\r\n4,5.25,60,1\r\n",
      "x;y;z;c\r\n1,5;-2;3;0,5\r\n4;5,25;60;1\r\n",
      "1.5\t-2\t3\t0.5\r4\t5.25\t60\t1\r",
      "# probe 2\n1.5  -2  3  0.5\n\n4 5.25 60 1",
      "\"x\",\"y\",\"z\",\"c\"\n\"1.5\",\"-2\",\"3\",\"0.5\"\n\"4\",\"5.25\",\"60\",\"1\"\n",
      "1.5, -2, 3, 0.5,\n+4, 5.25, 60, 1,\n",
      utf16le("x\ty\tz\tc\r\n1,5\t-2\t3\t0,5\r\n4\t5,25\t60\t1\r\n", true),
      utf16le("1.5,-2,3,0.5\n4,5.25,60,1\n", false),
  };
  for (size_t f = 0; f < forms.size(); ++f) {
    const auto points = read_points_csv(write(forms[f]));
    ASSERT_EQ(points.size(), 2u) << "form " << f;
    EXPECT_EQ(points[0].p_mm, Eigen::Vector3d(1.5, -2, 3)) << "form " << f;
    EXPECT_EQ(points[0].confidence, 0.5) << "form " << f;
    EXPECT_EQ(points[1].p_mm, Eigen::Vector3d(4, 5.25, 60)) << "form " << f;
    EXPECT_EQ(points[1].confidence, 1.0) << "form " << f;
  }
}

TEST_F(PointsFile, RefusesWhatNoPatientHasNamingTheRow) {
  EXPECT_EQ(error_of("x,y,z\n1,2,3\n1,2,12000\n"),
            ":3: coordinate 12000 mm lies beyond 10 m: no patient is there (mm are expected; "
            "metres or another column?)");
  EXPECT_EQ(error_of("1,2,3\n4,nan,6\n"), ":2: non-finite coordinate");
  EXPECT_EQ(error_of("1,2,3\n4,1e400,6\n"), ":2: non-finite coordinate");
  EXPECT_EQ(error_of("x,y,z\ny,x,z\n"), ":2: 'y' is not a number");
  EXPECT_EQ(error_of("1,2\n"), ":1: expected x,y,z[,confidence], got 2 columns");
  EXPECT_EQ(error_of(std::string("1,2,3\n\0\0\0", 9)),
            ": not a text file (neither UTF-8 nor UTF-16 text)");
  EXPECT_EQ(error_of("x,y,z\n"), ": no points in the file");
  // A cell of any length is echoed in at most 80 characters.
  EXPECT_EQ(error_of("1,2,3\n1,2," + std::string(5000, 'a') + "\n"),
            ":2: '" + std::string(80, 'a') + "...' is not a number");
}

TEST_F(PointsFile, ReadsTheCtItDeclaresWithItsPointsInOnePass) {
  const PointsCt ct{"1.2.3.4", "1.2.3.5"};
  for (const std::string ends : {"\n", "\r\n", "\r"}) {
    std::string text = points_ct_comment(ct) + "x,y,z\n1,2,3\n# a note: not a declaration\n";
    for (size_t at = text.find('\n'); at != std::string::npos;
         at = text.find('\n', at + ends.size()))
      text.replace(at, 1, ends);
    const PointsTable table = read_points_table(write(text));
    EXPECT_EQ(table.ct.series_instance_uid, "1.2.3.4");
    EXPECT_EQ(table.ct.frame_of_reference_uid, "1.2.3.5");
    ASSERT_EQ(table.points.size(), 1u);
    EXPECT_EQ(table.points[0].p_mm, Eigen::Vector3d(1, 2, 3));
  }
  EXPECT_TRUE(read_points_table(write("1,2,3\n")).ct.series_instance_uid.empty());
}

TEST_F(PointsFile, RefusesMoreThanTheLimit) {
  std::string many;
  for (long i = 0; i <= kMaxPointsInFile; ++i)
    many += "1,2,3\n";
  EXPECT_EQ(error_of(many), ": more than 100000 points (the most a points file may hold)");
  many.resize(many.size() - 6);
  EXPECT_EQ(read_points_csv(write(many)).size(), static_cast<size_t>(kMaxPointsInFile));
}

TEST(RepeatedPoints, EachPositionIsKeptOnceInTheFilesOrderWithItsFirstConfidence) {
  using fitting::AttractivePoint;
  std::vector<AttractivePoint> points = {{{1, 2, 3}, 0.5},   {{4, 5, 6}, 1.0}, {{1, 2, 3}, 1.0},
                                         {{1, 2, 3.001}, 1}, {{4, 5, 6}, 0.2}, {{-0.0, 0, 0}, 1},
                                         {{0, 0, 0}, 0.7}};
  EXPECT_EQ(drop_repeated_points(points), 3u);
  ASSERT_EQ(points.size(), 4u);
  EXPECT_EQ(points[0].p_mm, Eigen::Vector3d(1, 2, 3));
  EXPECT_EQ(points[0].confidence, 0.5);
  EXPECT_EQ(points[1].p_mm, Eigen::Vector3d(4, 5, 6));
  EXPECT_EQ(points[1].confidence, 1.0);
  EXPECT_EQ(points[2].p_mm, Eigen::Vector3d(1, 2, 3.001));  // near is not the same
  EXPECT_EQ(points[3].confidence, 1.0);                     // -0 and 0: one position
  std::vector<AttractivePoint> none;
  EXPECT_EQ(drop_repeated_points(none), 0u);
}

TEST_F(PointsFile, ARunFitsEachPositionOnceAndSaysHowManyRepeated) {
  std::string text = "x,y,z\n";
  for (int i = 0; i < 87; ++i)
    text += "-122.603,67.413,741.608\n";
  text += "-120,67.413,741.608\n";
  const ModelStageResult no_model;  // a file's points do not depend on the model
  PointsOptions o;
  o.source = "file";
  o.file = write(text);
  const PointsStageResult r = run_points_stage(o, no_model);
  ASSERT_EQ(r.points.size(), 2u);
  EXPECT_EQ(r.summary["count"], 2);
  EXPECT_EQ(r.summary["read"], 88);
  EXPECT_EQ(r.summary["repeated"], 86);
  ASSERT_EQ(r.warnings.size(), 1u);
  EXPECT_EQ(r.warnings[0], o.file.string() +
                               ": 86 of its 88 points repeat an earlier point's position exactly; "
                               "each position is fitted once (2 points)");
  o.file = write("1,2,3\n4,5,6\n");
  const PointsStageResult distinct = run_points_stage(o, no_model);
  EXPECT_TRUE(distinct.warnings.empty());
  EXPECT_FALSE(distinct.summary.contains("repeated"));
}

}  // namespace
}  // namespace organfit::pipeline
