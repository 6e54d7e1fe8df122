#pragma once
// Plain inputs for the VTK side (no Eigen, as for the ITK bridge).
#include <array>
#include <cstdint>
#include <string>
#include <vector>

namespace organfit::meshing {

struct PlainMask {
  std::array<int, 3> size{0, 0, 0};
  std::array<double, 3> spacing_mm{1, 1, 1}, origin_mm{0, 0, 0};
  std::array<double, 9> direction{1, 0, 0, 0, 1, 0, 0, 0, 1};  ///< row-major
  std::vector<std::uint8_t> labels;                            ///< i fastest; 1 inside
};

struct PlainSurfaceReport {
  long long points = 0, triangles = 0, boundary_edges = 0, non_manifold_edges = 0;
  double enclosed_volume_mm3 = 0, area_mm2 = 0, signed_volume_mm3 = 0;
};

/// Surface of the mask written to `file`; throws InputError (VTK side).
PlainSurfaceReport vtk_write_surface(const PlainMask& mask, const std::string& file);

}  // namespace organfit::meshing
