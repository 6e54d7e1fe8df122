// Eigen side of the meshing: plain inputs for the VTK side.
#include "organfit/meshing/surface.h"

#include "organfit/meshing/plain_mesh.h"
#include "point_file_check.h"

namespace organfit::meshing {

namespace {

SurfaceReport report_of(const PlainSurfaceReport& p) {
  SurfaceReport r;
  r.points = p.points;
  r.triangles = p.triangles;
  r.boundary_edges = p.boundary_edges;
  r.non_manifold_edges = p.non_manifold_edges;
  r.enclosed_volume_mm3 = p.enclosed_volume_mm3;
  r.area_mm2 = p.area_mm2;
  r.outward = p.signed_volume_mm3 > 0;
  return r;
}

}  // namespace

SurfaceReport write_surface(const geometry::LabelVolume& mask, const std::filesystem::path& file) {
  return report_of(vtk_write_surface(geometry::to_plain(mask), file.string()));
}

SurfaceReport write_surface(const geometry::LabelVolume& mask, const std::filesystem::path& file,
                            const std::string& name,
                            const std::function<double(const Eigen::Vector3d&)>& value) {
  const PointScalar scalar{
      name, [&value](const double* x) { return value(Eigen::Vector3d(x[0], x[1], x[2])); }};
  return report_of(vtk_write_surface(geometry::to_plain(mask), file.string(), false, &scalar));
}

SurfaceMesh surface_mesh(const geometry::LabelVolume& mask) {
  PlainSurfaceReport p = vtk_write_surface(geometry::to_plain(mask), "", true);
  SurfaceMesh out;
  out.report = report_of(p);
  out.vertex_mm = std::move(p.vertex_mm);
  out.triangle_ids = std::move(p.triangle_ids);
  return out;
}

std::vector<std::array<double, 4>> read_point_set(const std::filesystem::path& file) {
  detail::check_point_file_complete(file);
  const PlainPointSet p = vtk_read_points(file.string());
  std::vector<std::array<double, 4>> out;
  for (size_t i = 0; i < p.confidence.size(); ++i)
    out.push_back({p.xyz_mm[3 * i], p.xyz_mm[3 * i + 1], p.xyz_mm[3 * i + 2], p.confidence[i]});
  return out;
}

}  // namespace organfit::meshing
