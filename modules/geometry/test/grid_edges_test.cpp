// voxels_on_faces and side_of_face: an organ cut by its grid's edge, and which side of the
// patient that edge is.
#include "organfit/geometry/grid_edges.h"

#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <string>

namespace organfit::geometry {
namespace {

TEST(GridEdges, CountsTheOrgansVoxelsOnEachFace) {
  ImageGeometry g;
  g.size = {6, 5, 4};
  LabelVolume m(g);
  EXPECT_EQ(voxels_on_faces(m), (std::array<long long, 6>{0, 0, 0, 0, 0, 0}));
  for (int j = 1; j < 4; ++j)  // a bar along j through the middle of the last slice
    m.at(2, j, 3) = 1;
  m.at(0, 0, 0) = 1;  // a voxel at a corner lies on three faces
  EXPECT_EQ(voxels_on_faces(m), (std::array<long long, 6>{1, 0, 1, 0, 1, 3}));
  m.at(5, 4, 3) = 2;  // another label is not the organ
  EXPECT_EQ(voxels_on_faces(m), (std::array<long long, 6>{1, 0, 1, 0, 1, 3}));
}

TEST(GridEdges, NamesTheFacesSideInPatientCoordinates) {
  ImageGeometry g;
  const char* lps[6] = {"right", "left", "anterior", "posterior", "inferior", "superior"};
  for (int face = 0; face < 6; ++face)
    EXPECT_EQ(std::string(side_of_face(g, face)), lps[face]) << face;
  // A feet-first series: k runs inferiorly, i towards the right, j posteriorly.
  g.direction << -1, 0, 0, 0, 1, 0, 0, 0, -1;
  EXPECT_EQ(std::string(side_of_face(g, 5)), "inferior");
  EXPECT_EQ(std::string(side_of_face(g, 4)), "superior");
  EXPECT_EQ(std::string(side_of_face(g, 1)), "right");
  // An oblique axis: named by its largest component.
  g.direction = Eigen::AngleAxisd(0.3, Eigen::Vector3d::UnitX()).toRotationMatrix();
  EXPECT_EQ(std::string(side_of_face(g, 5)), "superior");
  EXPECT_EQ(std::string(side_of_face(g, 3)), "posterior");
}

}  // namespace
}  // namespace organfit::geometry
