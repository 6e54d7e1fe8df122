#include "organfit/meshing/surface.h"

#include <gtest/gtest.h>
#include <unistd.h>

#include <Eigen/Geometry>

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

}  // namespace
}  // namespace organfit::meshing
