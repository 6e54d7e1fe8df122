#pragma once
// Plain inputs for the VTK side (no Eigen, as for the ITK bridge).
#include <array>
#include <cstdint>
#include <functional>
#include <string>
#include <vector>

#include "organfit/geometry/plain_image.h"

namespace organfit::meshing {

using geometry::PlainMask;  // label 1 inside

struct PlainSurfaceReport {
  long long points = 0, triangles = 0, boundary_edges = 0, non_manifold_edges = 0;
  double enclosed_volume_mm3 = 0, area_mm2 = 0, signed_volume_mm3 = 0;
  std::vector<float> vertex_mm;   ///< x, y, z per point (filled when asked for)
  std::vector<int> triangle_ids;  ///< three point indices per triangle (idem)
};

/// A value at each point of the written surface (e.g. the uncertainty, sigma_mm).
struct PointScalar {
  std::string name;                            ///< the point array's name
  std::function<double(const double*)> at_mm;  ///< its value at x, y, z (mm)
};

/// Why `file` cannot be written as a mesh, or empty when it can: its name must end in one
/// of vtk_write_surface's formats, .stl, .vtp, .ply or .obj.
std::string mesh_file_name_problem(const std::string& file);

/// Surface of the mask written to `file` (none when empty); with `keep_mesh` the
/// report carries the triangles; with `scalar` the points carry it: a point array in
/// .vtp, vertex colours in .ply (blue 0 to red at its largest; the range in a header
/// comment: VTK 9.1's PLY writer has no scalar properties), nothing in .stl and .obj.
/// Throws InputError (VTK side).
PlainSurfaceReport vtk_write_surface(const PlainMask& mask, const std::string& file,
                                     bool keep_mesh = false, const PointScalar* scalar = nullptr);

struct PlainPointSet {
  std::vector<double> xyz_mm;      ///< x, y, z per point
  std::vector<double> confidence;  ///< the "confidence" point array, else 1
};

/// Points of a .ply, legacy .vtk or .vtp file (VTK side). Throws InputError naming the file.
PlainPointSet vtk_read_points(const std::string& file);

}  // namespace organfit::meshing
