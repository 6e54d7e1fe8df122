#pragma once
// The organ's surface as a mesh: closed (watertight, manifold), consistently oriented
// outward, smooth (no bumps of single particles or voxels).
//
//   mask --vtkFlyingEdges3D (level 0.5)--> triangles through voxel-centre boundaries
//        --vtkWindowedSincPolyDataFilter (20 iterations, pass band 0.1)--> smooth,
//          volume-preserving smoothing (no shrinkage, unlike Laplacian)
//        --vtkPolyDataNormals (consistent, auto-oriented outward)-->
// The mask is padded by one empty voxel so the surface closes at the grid's border.
#include <array>
#include <filesystem>
#include <functional>
#include <string>
#include <vector>

#include "organfit/geometry/image_geometry.h"

namespace organfit::meshing {

struct SurfaceReport {
  long long points = 0, triangles = 0;
  long long boundary_edges = 0, non_manifold_edges = 0;  ///< 0 and 0: watertight, manifold
  double enclosed_volume_mm3 = 0;                        ///< vtkMassProperties
  double area_mm2 = 0;
  bool outward = false;  ///< signed volume positive: normals point out
};

/// Builds the surface of label 1 in `mask`, writes it to `file` (format by extension:
/// .stl binary, .vtp, .ply, .obj; temporary name then rename) and reports on it. Throws
/// InputError naming the file on an unknown extension or a failed write, or when the
/// mask is empty.
SurfaceReport write_surface(const geometry::LabelVolume& mask, const std::filesystem::path& file);
/// The same with a value at each point (`name`, e.g. sigma_mm): a point array in .vtp,
/// vertex colours in .ply (blue 0 to red at its largest), nothing in .stl and .obj.
SurfaceReport write_surface(const geometry::LabelVolume& mask, const std::filesystem::path& file,
                            const std::string& name,
                            const std::function<double(const Eigen::Vector3d&)>& value);

/// The same surface as triangles, not written (for the report's 3D view).
struct SurfaceMesh {
  std::vector<float> vertex_mm;  ///< x, y, z per vertex, patient mm
  std::vector<int>
      triangle_ids;  ///< three vertex indices per triangle, outward (counter-clockwise)
  SurfaceReport report;
};
SurfaceMesh surface_mesh(const geometry::LabelVolume& mask);

/// A point set from a mesh file's vertices (.ply, legacy .vtk, .vtp), with its
/// "confidence" point array when it has one: x, y, z, confidence per point.
std::vector<std::array<double, 4>> read_point_set(const std::filesystem::path& file);

}  // namespace organfit::meshing
