#include "organfit/pipeline/points_file.h"

#include <fmt/format.h>
#include <gtest/gtest.h>
#include <unistd.h>

#include <cmath>
#include <fstream>

#include "organfit/pipeline/points_stage.h"
#include "organfit/pipeline/scene_schema.h"
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

// A header's unit and frame are read, not ignored: the numbers are taken as mm LPS, so a
// header saying otherwise is refused on its line.
TEST_F(PointsFile, RefusesAHeaderNamingAnotherUnitOrFrame) {
  const std::string why = "; points are read in mm, in the planning CT's patient coordinates (LPS)";
  EXPECT_EQ(error_of("x_cm,y_cm,z_cm\n1,2,3\n"), ":1: its columns are named in centimetres" + why);
  EXPECT_EQ(error_of("# probe\nX (m);Y (m);Z (m)\n1;2;3\n"),
            ":2: its columns are named in metres" + why);
  EXPECT_EQ(error_of("pos_x_metres,pos_y_metres,pos_z_metres,confidence\n1,2,3,1\n"),
            ":1: its columns are named in metres" + why);
  EXPECT_EQ(error_of("x inches,y inches,z inches\n1,2,3\n"),
            ":1: its columns are named in inches" + why);
  const std::string ras =
      ": its columns are named in RAS (as 3D Slicer's are): x and y point the other way" + why;
  EXPECT_EQ(error_of("R,A,S\n1,2,3\n"), ":1" + ras);
  EXPECT_EQ(error_of("x_ras,y_ras,z_ras\n1,2,3\n"), ":1" + ras);
  EXPECT_EQ(error_of("R (mm),A (mm),S (mm)\n1,2,3\n"), ":1" + ras);
  EXPECT_EQ(error_of("id,x_cm,y_cm,z_cm\n7,1,2,3\n"),
            ":1: its columns are named in centimetres" + why);
  EXPECT_EQ(error_of("label,note,x (m),y (m),z (m)\np,q,1,2,3\n"),
            ":1: its columns are named in metres" + why);
  EXPECT_EQ(error_of("S,P,L\n1,2,3\n"),
            ":1: its columns are named s, p, l: they are read as l, p, s" + why);
  EXPECT_EQ(error_of("i,j,k\n1,2,3\n"),
            ":1: its columns are named i, j, k: voxel indices, not positions" + why);
  // mm, LPS, or no unit at all: read.
  for (const std::string header : {"x_mm,y_mm,z_mm,confidence", "X (mm),Y (mm),Z (mm)", "x,y,z",
                                   "L,P,S", "x in mm,y in mm,z in mm", "xmm,ymm,zmm", "a,b,c",
                                   "x,y,z,m",  // a fourth column is not a coordinate
                                   "m1,m2,m3", "P1 (mm),P2 (mm),P3 (mm)"})  // numbered, not m
    EXPECT_EQ(read_points_csv(write(header + "\n1,2,3\n")).size(), 1u) << header;
}

// 3D Slicer's markups table: its declared columns (an id and a label beside x, y, z) and
// its frame (RAS negated into LPS; Slicer 4's 0 and 1). A declaration it cannot read, or a
// row short of its columns, is refused naming the line.
TEST_F(PointsFile, ReadsSlicerMarkupsByTheirDeclaredColumnsAndFrame) {
  const std::string head =
      "# Markups fiducial file version = 4.11\n# CoordinateSystem = {}\n"
      "# columns = id,x,y,z,ow,ox,oy,oz,vis,sel,lock,label,desc,associatedNodeID\n";
  const std::string rows =
      "vtkMRMLMarkupsFiducialNode_0,1.5,-2,30,0,0,0,1,1,1,0,F-1,,\n"
      "vtkMRMLMarkupsFiducialNode_1,-4,5.25,31,0,0,0,1,1,1,0,F-2,a note,\n";
  for (const auto& [frame, sign] :
       std::vector<std::pair<std::string, double>>{{"LPS", 1}, {"1", 1}, {"RAS", -1}, {"0", -1}}) {
    const std::string text = fmt::format(fmt::runtime(head), frame) + rows;
    const std::vector<fitting::AttractivePoint> p = read_points_csv(write(text));
    ASSERT_EQ(p.size(), 2u) << frame;
    EXPECT_EQ(p[0].p_mm, Eigen::Vector3d(sign * 1.5, sign * -2, 30)) << frame;
    EXPECT_EQ(p[1].p_mm, Eigen::Vector3d(sign * -4, sign * 5.25, 31)) << frame;
    EXPECT_EQ(p[1].confidence, 1.0);
  }
  EXPECT_EQ(error_of(fmt::format(fmt::runtime(head), "IJK") + rows),
            ":2: CoordinateSystem 'IJK': LPS or RAS expected");
  EXPECT_EQ(error_of("# columns = id,a,b,c\n" + rows),
            ":1: its declared columns name no x, y and z: id,a,b,c");
  EXPECT_EQ(error_of(fmt::format(fmt::runtime(head), "LPS") + "id_0,1,2\n"),
            ":4: 3 columns where its named columns need 4");
  // Its first row is a row, not a header: text where a coordinate is is refused.
  EXPECT_EQ(error_of(fmt::format(fmt::runtime(head), "LPS") + "id_0,one,2,3\n" + rows),
            ":4: 'one' is not a number");
}

// A header line that names x, y and z other than first, second and third ("id,x,y,z", as
// spreadsheets of marked points have; "z,y,x"): those columns read, and one named
// confidence; their names' units and frame judged as a header's are. The id had been read
// as x and z as a confidence ("confidence must be in (0, 1]"). A header naming x, y, z
// first keeps its fourth column as the confidence, whatever its name.
TEST_F(PointsFile, ReadsTheColumnsAHeaderNamesXYZ) {
  auto read = [&](const std::string& text) { return read_points_csv(write(text)); };
  std::vector<fitting::AttractivePoint> p = read("id,x,y,z\n7,1.5,-2,30\n8,-4,5,31\n");
  ASSERT_EQ(p.size(), 2u);
  EXPECT_EQ(p[0].p_mm, Eigen::Vector3d(1.5, -2, 30));
  EXPECT_EQ(p[1].p_mm, Eigen::Vector3d(-4, 5, 31));
  EXPECT_EQ(p[1].confidence, 1.0);
  p = read("label;Z (mm);X (mm);Y (mm);confidence\np1;30;1,5;-2;0,5\n");
  ASSERT_EQ(p.size(), 1u);
  EXPECT_EQ(p[0].p_mm, Eigen::Vector3d(1.5, -2, 30));
  EXPECT_EQ(p[0].confidence, 0.5);
  p = read("x,y,z,weight\n1,2,3,0.25\n");
  EXPECT_EQ(p[0].confidence, 0.25);
  EXPECT_EQ(error_of("id,x,y,z\n7,1.5,-2\n"), ":2: 3 columns where its named columns need 4");
  // Named in another order: read by their names (they had been refused, read by place).
  p = read("z,y,x\n30,-2,1.5\n");
  EXPECT_EQ(p[0].p_mm, Eigen::Vector3d(1.5, -2, 30));
  p = read("Y (mm),X (mm),Z (mm),confidence\n-2,1.5,30,0.75\n");
  EXPECT_EQ(p[0].p_mm, Eigen::Vector3d(1.5, -2, 30));
  EXPECT_EQ(p[0].confidence, 0.75);
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

/// A body of the given centre (mm), an egg of 40 x 30 x 50 mm, and 87 points on the +y half
/// of its surface (mm), found along rays from its centre by bisection to 1e-3 mm.
struct EggAndPoints {
  ModelStageResult model;
  std::vector<fitting::AttractivePoint> points;
};
EggAndPoints egg_and_points(const Eigen::Vector3d& centre_mm) {
  const std::string c = std::to_string(centre_mm.x()) + ", " + std::to_string(centre_mm.y()) +
                        ", " + std::to_string(centre_mm.z());
  const config::Scene scene =
      config::parse_scene("body:\n  shape: egg\n  size_mm: [40, 30, 50]\n  centre_mm: [" + c +
                              "]\nmodel:\n  radius_mm: 2.5\n",
                          fs::temp_directory_path() / "units.yaml", scene_schema());
  check_scene_rules(scene);
  EggAndPoints e{run_model_stage(model_stage_options_from(scene)), {}};
  for (int k = 0; k < 87; ++k) {
    // A Fibonacci spiral over the half sphere y > 0.
    const double y = (k + 0.5) / 87.0, r = std::sqrt(1 - y * y), a = k * 2.399963229728653;
    const Eigen::Vector3d dir(r * std::cos(a), y, r * std::sin(a));
    double in = 0, out = 60;
    while (out - in > 1e-3) {
      const double mid = 0.5 * (in + out);
      (e.model.shape.inside(centre_mm + mid * dir) ? in : out) = mid;
    }
    e.points.push_back({centre_mm + in * dir, 1.0});
  }
  return e;
}

std::vector<fitting::AttractivePoint> scaled(
    std::vector<fitting::AttractivePoint> points, double by,
    const Eigen::Vector3d& shift_mm = Eigen::Vector3d::Zero()) {
  for (auto& p : points)
    p.p_mm = by * (p.p_mm + shift_mm);
  return points;
}

std::string unit_error(const std::vector<fitting::AttractivePoint>& points,
                       const fitting::OrganModel& model) {
  try {
    check_points_unit(points, model, "today.csv");
  } catch (const InputError& e) {
    return e.what();
  }
  return "no error";
}

TEST(PointsUnit, CentimetresAndMetresAreRefusedWhereTheOrganIsNearTheOrigin) {
  // An organ about the patient origin: points in cm lie inside it, and a fit would move the
  // organ onto them (the global stage's reach is 100 mm).
  const EggAndPoints e = egg_and_points({2, -3, 4});
  EXPECT_EQ(unit_error(e.points, e.model), "no error");
  const std::string cm = unit_error(scaled(e.points, 0.1), e.model);
  EXPECT_EQ(cm.rfind("today.csv: the points look written in centimetres: times 10 they lie a "
                     "median 0.",
                     0),
            0u)
      << cm;
  EXPECT_NE(cm.find("patient coordinates are in mm"), std::string::npos);
  EXPECT_NE(unit_error(scaled(e.points, 0.001), e.model).find("written in metres: times 1000"),
            std::string::npos);
  // Today's organ moved 12 mm and the points in cm: still refused.
  EXPECT_NE(unit_error(scaled(e.points, 0.1, {6, -8, 7}), e.model).find("centimetres"),
            std::string::npos);
  // The same move in mm is a change to fit, not a unit.
  EXPECT_EQ(unit_error(scaled(e.points, 1, {6, -8, 7}), e.model), "no error");
  // A cluster in the organ's middle is at no unit's scale: not called one.
  EXPECT_EQ(unit_error(scaled(e.points, 1.0 / 30), e.model), "no error");
}

TEST(PointsUnit, CentimetresAreRefusedFarFromTheOriginToo) {
  const EggAndPoints e = egg_and_points({-101, 44, 720});  // ct-sts-004's GTV's place
  EXPECT_EQ(unit_error(e.points, e.model), "no error");
  EXPECT_NE(unit_error(scaled(e.points, 0.1), e.model).find("centimetres"), std::string::npos);
  EXPECT_EQ(unit_error(scaled(e.points, 1, {5, 5, -5}), e.model), "no error");
}

}  // namespace
}  // namespace organfit::pipeline
