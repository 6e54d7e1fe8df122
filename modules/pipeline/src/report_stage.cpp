#include "organfit/pipeline/report_stage.h"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>

#include "organfit/geometry/mask_ops.h"
#include "organfit/geometry/shape.h"
#include "organfit/meshing/surface.h"
#include "organfit/report/report.h"
#include "organfit/support/parallel.h"
#include "organfit/support/progress.h"

namespace organfit::pipeline {

std::string build_report(const ReportContext& c) {
  report::ReportInput in;
  in.run = c.run;
  in.scene_yaml = c.scene_yaml;
  in.history_csv = c.history_csv;
  in.points_mm = c.points_mm;
  in.residuals_mm = c.residuals_mm;
  if (c.show_patient && c.ct)
    in.patient = c.ct->patient.patient_name + " (ID " + c.ct->patient.patient_id + ")";
  Progress progress("report", 2);
  std::function<double(const Eigen::Vector3d&)> sigma;
  if (c.uncertainty) {
    in.sigma_scale_mm = c.uncertainty->far_sd_mm();
    sigma = [u = c.uncertainty](const Eigen::Vector3d& x) { return u->sd_mm(x); };
  }
  if (c.fitted) {
    // The fitted surface as the mesh export makes it (the organ on a grid of rho).
    const geometry::LabelVolume body =
        c.fitted_on_mesh_grid
            ? *c.fitted_on_mesh_grid
            : c.fitted->on_grid(geometry::grid_covering(c.fitted->bounds(), c.rho_mm, c.rho_mm));
    meshing::SurfaceMesh mesh = meshing::surface_mesh(body);
    progress.update(1, "the 3D view");
    in.surface_vertex_mm = std::move(mesh.vertex_mm);
    if (sigma) {  // each vertex its own, on threads (55,000 on a 1.5 L liver: 0.1 s on one)
      const auto& xyz = in.surface_vertex_mm;
      const long long vertices = static_cast<long long>(xyz.size() / 3);
      in.surface_sigma_mm.resize(static_cast<size_t>(vertices));
#pragma omp parallel for schedule(dynamic, 256)
      for (long long v = 0; v < vertices; ++v) {
        const size_t at = 3 * static_cast<size_t>(v);
        in.surface_sigma_mm[static_cast<size_t>(v)] =
            static_cast<float>(sigma(Eigen::Vector3d(xyz[at], xyz[at + 1], xyz[at + 2])));
      }
    }
    in.surface_triangles = std::move(mesh.triangle_ids);
  }
  if (c.ct && c.fitted) {
    const auto& g = c.ct->geometry;
    const geometry::LabelVolume fitted = c.fitted_on_ct ? *c.fitted_on_ct : c.fitted->on_grid(g);
    const geometry::LabelVolume planning =
        c.planning ? geometry::shape_on_grid(*c.planning, g,
                                             geometry::index_range(g, c.planning->bounds(), 1))
                   : geometry::LabelVolume(g);
    std::array<int, 3> lo{g.size[0], g.size[1], g.size[2]}, hi{-1, -1, -1};
    Eigen::Vector3d centroid = Eigen::Vector3d::Zero();
    long long n = 0;
    for (int k = 0; k < g.size[2]; ++k)
      for (int j = 0; j < g.size[1]; ++j)
        for (int i = 0; i < g.size[0]; ++i) {
          const bool f = fitted.at(i, j, k) == 1, p = planning.at(i, j, k) == 1;
          if (!f && !p) continue;
          const int idx[3] = {i, j, k};
          for (int d = 0; d < 3; ++d)
            lo[d] = std::min(lo[d], idx[d]), hi[d] = std::max(hi[d], idx[d]);
          if (f) centroid += Eigen::Vector3d(i, j, k), ++n;
        }
    if (n > 0) {
      centroid /= static_cast<double>(n);
      const std::array<int, 3> organ_lo = lo, organ_hi = hi;
      for (int d = 0; d < 3; ++d) {
        const int margin = static_cast<int>(std::ceil(25.0 / g.spacing_mm[d]));
        lo[d] = std::max(0, lo[d] - margin), hi[d] = std::min(g.size[d] - 1, hi[d] + margin);
      }
      const geometry::LabelVolume* plan = c.planning ? &planning : nullptr;
      in.window = report::choose_window(g, c.ct->hu, c.planning ? planning : fitted);
      const double slab = 0.5 * g.spacing_mm.maxCoeff() + 1.0;
      // Every axial slice through the organ (planning or fitted), browsable; each its own,
      // on threads.
      in.axial.resize(static_cast<size_t>(organ_hi[2] - organ_lo[2] + 1));
      parallel_for_each(static_cast<int>(in.axial.size()), [&](int s) {
        in.axial[static_cast<size_t>(s)] =
            report::slice_view(g, c.ct->hu, report::Plane::kAxial, organ_lo[2] + s, lo, hi, plan,
                               &fitted, c.points_mm, c.residuals_mm, slab, sigma);
      });
      in.axial_shown = static_cast<int>(std::lround(centroid[2])) - organ_lo[2];
      for (auto [plane, axis] :
           {std::pair{report::Plane::kCoronal, 1}, std::pair{report::Plane::kSagittal, 0}})
        in.views.push_back(
            report::slice_view(g, c.ct->hu, plane, static_cast<int>(std::lround(centroid[axis])),
                               lo, hi, plan, &fitted, c.points_mm, c.residuals_mm, slab, sigma));
    }
  }
  progress.update(2, "the CT views");
  return report::report_html(in);
}

}  // namespace organfit::pipeline
