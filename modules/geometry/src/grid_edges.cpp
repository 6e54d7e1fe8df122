#include "organfit/geometry/grid_edges.h"

namespace organfit::geometry {

std::array<long long, 6> voxels_on_faces(const LabelVolume& mask) {
  std::array<long long, 6> on{};
  const ImageGeometry& g = mask.geometry;
  for (int k = 0; k < g.size[2]; ++k)
    for (int j = 0; j < g.size[1]; ++j)
      for (int i = 0; i < g.size[0]; ++i) {
        if (mask.at(i, j, k) != 1) continue;
        const int at[3] = {i, j, k};
        for (int a = 0; a < 3; ++a) {
          on[static_cast<size_t>(2 * a)] += at[a] == 0;
          on[static_cast<size_t>(2 * a + 1)] += at[a] == g.size[a] - 1;
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
