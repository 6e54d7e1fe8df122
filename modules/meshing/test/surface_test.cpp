#include "organfit/meshing/surface.h"

#include <gtest/gtest.h>
#include <unistd.h>

#include <Eigen/Geometry>
#include <fstream>

#include "organfit/support/error.h"

namespace fs = std::filesystem;

namespace organfit::meshing {
namespace {

geometry::LabelVolume ellipsoid_mask(const Eigen::Matrix3d& direction) {
  geometry::ImageGeometry g;
  g.size = {70, 60, 40};
  g.spacing_mm = {0.8, 0.8, 1.5};
  g.origin_mm = {-20, 10, -300};
  g.direction = direction;
  geometry::LabelVolume m(g);
  const Eigen::Vector3d centre = g.index_to_physical(Eigen::Vector3d(35, 30, 20));
  for (int k = 0; k < 40; ++k)
    for (int j = 0; j < 60; ++j)
      for (int i = 0; i < 70; ++i) {
        const Eigen::Vector3d p = g.index_to_physical(Eigen::Vector3d(i, j, k)) - centre;
        m.at(i, j, k) = p.cwiseQuotient(Eigen::Vector3d(22, 17, 20)).squaredNorm() <= 1;
      }
  return m;
}

TEST(Surface, WatertightManifoldOutwardAndEnclosingTheMasksVolume) {
  const fs::path dir = fs::temp_directory_path() / ("organfit_mesh_" + std::to_string(getpid()));
  fs::create_directories(dir);
  for (const Eigen::Matrix3d& dir_matrix :
       {Eigen::Matrix3d(Eigen::Matrix3d::Identity()),
        Eigen::Matrix3d(
            Eigen::AngleAxisd(0.4, Eigen::Vector3d(1, 2, 3).normalized()).toRotationMatrix())}) {
    const geometry::LabelVolume mask = ellipsoid_mask(dir_matrix);
    for (const char* name : {"s.stl", "s.vtp", "s.ply", "s.obj"}) {
      const SurfaceReport r = write_surface(mask, dir / name);
      EXPECT_EQ(r.boundary_edges, 0) << name;
      EXPECT_EQ(r.non_manifold_edges, 0) << name;
      EXPECT_TRUE(r.outward) << name;
      EXPECT_NEAR(r.enclosed_volume_mm3, mask.volume_mm3(1), 0.03 * mask.volume_mm3(1)) << name;
      EXPECT_GT(fs::file_size(dir / name), 1000u);
    }
  }
  EXPECT_THROW(write_surface(ellipsoid_mask(Eigen::Matrix3d::Identity()), dir / "s.xyz"),
               InputError);
  geometry::ImageGeometry g;
  g.size = {4, 4, 4};
  EXPECT_THROW(write_surface(geometry::LabelVolume(g), dir / "e.stl"), InputError);
  EXPECT_EQ(std::distance(fs::directory_iterator(dir), fs::directory_iterator()),
            4);  // no temporaries
  fs::remove_all(dir);
}

// A point file's data against its header: VTK 9.1 reads a file cut short without a word,
// the points it lacks as copies or zeros.
TEST(ReadPointSet, AFileCutShortOrDamagedIsRefusedNamingItAndAWholeOneIsRead) {
  const fs::path dir = fs::temp_directory_path() / ("organfit_points_" + std::to_string(getpid()));
  fs::create_directories(dir);
  auto write = [&](const std::string& name, const std::string& text) {
    std::ofstream(dir / name, std::ios::binary) << text;
    return dir / name;
  };
  auto refusal = [](const fs::path& file) -> std::string {
    try {
      read_point_set(file);
    } catch (const InputError& e) {
      return e.what();
    }
    return "";
  };
  const std::string ply =
      "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
      "property float z\nend_header\n";
  EXPECT_EQ(read_point_set(write("whole.ply", ply + "1 2 3\n4 5 6\n7 8 9\n")).size(), 3u);
  EXPECT_EQ(refusal(write("cut.ply", ply + "1 2 3\n4 5 6\n")),
            (dir / "cut.ply").string() +
                ": its header declares 3 vertices, but the file holds 2: cut short or damaged");
  EXPECT_NE(refusal(write("short_line.ply", ply + "1 2 3\n4 5\n7 8 9\n"))
                .find(":9: vertex 2 has 2 values"),
            std::string::npos);
  EXPECT_NE(
      refusal(write("token.ply", ply + "1 2 3\n4 5x 6\n7 8 9\n")).find(":9: '5x' is not a number"),
      std::string::npos);
  EXPECT_NE(refusal(write("extra.ply", ply + "1 2 3\n4 5 6\n7 8 9\n1 1 1\n"))
                .find("data beyond the 3 vertices"),
            std::string::npos);
  // Binary: the vertices' bytes exactly (faces after them are not read as points).
  std::string bin =
      "ply\nformat binary_little_endian 1.0\nelement vertex 2\nproperty float x\nproperty float "
      "y\nproperty float z\nend_header\n";
  const std::string floats(24, '\0');  // 2 vertices of 3 floats, all 0 and 0
  EXPECT_EQ(read_point_set(write("whole_bin.ply", bin + floats)).size(), 2u);
  EXPECT_NE(refusal(write("cut_bin.ply", bin + floats.substr(0, 20)))
                .find("(24 bytes of data), but the file holds 20 bytes"),
            std::string::npos);
  // Legacy VTK: 3 n numbers after POINTS n.
  const std::string vtk =
      "# vtk DataFile Version 3.0\np\nASCII\nDATASET POLYDATA\nPOINTS 2 float\n";
  EXPECT_EQ(read_point_set(write("whole.vtk", vtk + "1 2 3 4 5 6\nVERTICES 1 3\n2 0 1\n")).size(),
            2u);
  EXPECT_NE(refusal(write("cut.vtk", vtk + "1 2 3 4 5\n"))
                .find("POINTS declares 2 points (6 values), but the file holds 5 values"),
            std::string::npos);
  EXPECT_NE(refusal(write("token.vtk", vtk + "1 2 3 --4 5 6\n"))
                .find("point value 4 of 6, '--4', is not a number"),
            std::string::npos);
  fs::remove_all(dir);
}

}  // namespace
}  // namespace organfit::meshing
