// Eigen side of the meshing: plain inputs for the VTK side.
#include "organfit/meshing/surface.h"

#include "organfit/meshing/plain_mesh.h"

namespace organfit::meshing {

SurfaceReport write_surface(const geometry::LabelVolume& mask, const std::filesystem::path& file) {
  PlainMask m;
  const auto& g = mask.geometry;
  m.size = g.size;
  for (int d = 0; d < 3; ++d) {
    m.spacing_mm[d] = g.spacing_mm[d];
    m.origin_mm[d] = g.origin_mm[d];
    for (int e = 0; e < 3; ++e) m.direction[3 * d + e] = g.direction(d, e);
  }
  m.labels = mask.labels;
  const PlainSurfaceReport p = vtk_write_surface(m, file.string());
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

}  // namespace organfit::meshing
