#include "organfit/geometry/grid_edges.h"

namespace organfit::geometry {

std::array<long long, 6> voxels_on_faces(const LabelVolume& mask) {
  // The faces' planes alone (a CT of 512 x 512 x 134 has 35M voxels, its faces 0.8M).
  std::array<long long, 6> on{};
  const ImageGeometry& g = mask.geometry;
  for (int a = 0; a < 3; ++a) {
    const int b = (a + 1) % 3, c = (a + 2) % 3;
    for (int side = 0; side < 2; ++side) {
      const int at_a = side ? g.size[a] - 1 : 0;
      long long count = 0;
      for (int v = 0; v < g.size[c]; ++v)
        for (int u = 0; u < g.size[b]; ++u) {
          int at[3];
          at[a] = at_a, at[b] = u, at[c] = v;
          count += mask.at(at[0], at[1], at[2]) == 1;
        }
      on[static_cast<size_t>(2 * a + side)] = count;
    }
  }
  return on;
}

const char* side_of_face(const ImageGeometry& g, int face) {
  const Eigen::Vector3d outward = (face % 2 ? 1.0 : -1.0) * g.direction.col(face / 2);
  Eigen::Index a = 0;
  outward.cwiseAbs().maxCoeff(&a);
  static const char* const names[3][2] = {
      {"right", "left"}, {"anterior", "posterior"}, {"inferior", "superior"}};
  return names[a][outward[a] > 0 ? 1 : 0];
}

}  // namespace organfit::geometry
