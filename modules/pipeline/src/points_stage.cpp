#include "organfit/pipeline/points_stage.h"

#include <fmt/format.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <set>
#include <tuple>
#include <utility>

#include "organfit/meshing/surface.h"
#include "organfit/pipeline/scene_schema.h"
#include "organfit/support/error.h"

namespace fs = std::filesystem;

namespace organfit::pipeline {

PointsTable read_points_file(const fs::path& file) {
  const std::string ext = file.extension().string();
  if (ext != ".ply" && ext != ".vtk" && ext != ".vtp") return read_points_table(file);
  PointsTable table;  // a mesh's vertices declare no CT
  for (const auto& p : meshing::read_point_set(file)) {
    if (!(std::isfinite(p[0]) && std::isfinite(p[1]) && std::isfinite(p[2])))
      throw InputError(file.string() + ": a point has a non-finite coordinate");
    if (!(p[3] > 0 && p[3] <= 1))
      throw InputError(file.string() + ": a confidence is outside (0, 1]");
    table.points.push_back({Eigen::Vector3d(p[0], p[1], p[2]), p[3]});
  }
  if (table.points.empty()) throw InputError(file.string() + ": no points in the file");
  return table;
}

size_t drop_repeated_points(std::vector<fitting::AttractivePoint>& points) {
  std::set<std::tuple<double, double, double>> seen;  // -0 and 0: one position
  size_t kept = 0;
  for (size_t i = 0; i < points.size(); ++i) {
    const Eigen::Vector3d& p = points[i].p_mm;
    if (seen.emplace(p.x(), p.y(), p.z()).second) points[kept++] = points[i];
  }
  const size_t dropped = points.size() - kept;
  points.resize(kept);
  return dropped;
}

void check_points_unit(const std::vector<fitting::AttractivePoint>& points,
                       const fitting::OrganModel& model, const fs::path& file) {
  if (points.empty() || model.state.size() == 0) return;
  auto median_distance_mm = [&](double scale) {
    Eigen::Matrix3Xd p(3, static_cast<Eigen::Index>(points.size()));
    for (size_t k = 0; k < points.size(); ++k)
      p.col(static_cast<Eigen::Index>(k)) = scale * points[k].p_mm;
    std::vector<double> d = fitting::planning_surface_distance_mm(model, p);
    std::nth_element(d.begin(), d.begin() + static_cast<std::ptrdiff_t>(d.size() / 2), d.end());
    return d[d.size() / 2];
  };
  // mm, cm and m: the unit whose points lie nearest the surface, if it is not mm and they lie
  // nearer the surface than halfway to the organ's middle.
  const geometry::Aabb box = model.shape.bounds();
  const double halfway_mm = 0.25 * box.size_mm().minCoeff();
  const std::array<std::pair<double, const char*>, 3> units = {
      {{1.0, "mm"}, {10.0, "centimetres"}, {1000.0, "metres"}}};
  std::array<double, 3> distance_mm{};
  for (size_t u = 0; u < units.size(); ++u)
    distance_mm[u] = median_distance_mm(units[u].first);
  const size_t nearest = static_cast<size_t>(
      std::min_element(distance_mm.begin(), distance_mm.end()) - distance_mm.begin());
  if (nearest != 0 && distance_mm[nearest] <= halfway_mm)
    throw InputError(fmt::format(
        "{}: the points look written in {}: times {:g} they lie a median {:.1f} mm from the "
        "planning organ's surface, as given {:.1f} mm; patient coordinates are in mm",
        file.string(), units[nearest].second, units[nearest].first, distance_mm[nearest],
        distance_mm[0]));
}

evaluation::Deformation deformation_about(evaluation::Deformation d, const geometry::Shape& shape) {
  d.centre_mm = shape.centre_mm;
  d.half_length_mm = 0.5 * shape.size_mm.x() * d.stretch;
  return d;
}

evaluation::Deformation true_deformation_from(const config::Scene& scene) {
  evaluation::Deformation d = keys::points_deformation().read(scene);
  d.twist_rad = scene.number("points", "twist_deg") * M_PI / 180;
  return d;
}

PointsOptions points_options_from(const config::Scene& scene) {
  PointsOptions o;
  o.source = scene.text("points", "source");
  if (o.source == "file") {
    o.file = scene.path("points", "file");
    return o;
  }
  o.deformation = true_deformation_from(scene);
  o.sampling = keys::points_sampling().read(scene);
  o.sampling.count = static_cast<int>(scene.integer("points", "count"));
  o.sampling.half_coverage = scene.text("points", "coverage") == "half";
  o.sampling.seed = static_cast<unsigned>(scene.integer("scene", "seed"));
  o.target_shape = scene.text("points", "target_shape");
  o.target_size_mm = scene.vec3("points", "target_size_mm");
  return o;
}

PointsStageResult run_points_stage(const PointsOptions& o, const ModelStageResult& model) {
  PointsStageResult r;
  if (o.source == "file") {
    PointsTable table = read_points_file(o.file);
    r.points = std::move(table.points);
    r.declared_ct = table.ct;
    const size_t read = r.points.size();
    const size_t repeated = drop_repeated_points(r.points);
    r.summary = {{"source", "file"}, {"count", r.points.size()}};
    if (repeated > 0) {
      r.summary["read"] = read;
      r.summary["repeated"] = repeated;
      r.warnings.push_back(fmt::format(
          "{}: {} of its {} points repeat an earlier point's position exactly; each position is "
          "fitted once ({} point{})",
          o.file.string(), repeated, read, r.points.size(), r.points.size() == 1 ? "" : "s"));
    }
    return r;
  }
  // The shape the points come from: the body itself, or another of the same volume.
  r.truth_shape = model.shape;
  if (o.target_shape != "same") {
    geometry::Shape t =
        geometry::make_shape(o.target_shape, o.target_size_mm, model.shape.centre_mm);
    const double voxel = 0.25 * model.cohesion.r0_mm;
    const double scale = std::cbrt(geometry::shape_volume_mm3(model.shape, voxel) /
                                   geometry::shape_volume_mm3(t, voxel));
    t.size_mm *= scale;
    r.truth_shape = t;
  }
  const evaluation::Deformation d = deformation_about(o.deformation, r.truth_shape);
  r.points = evaluation::sample_deformed_surface(r.truth_shape, d, o.sampling);
  r.truth = d;
  r.summary = {{"source", "generate"},
               {"count", r.points.size()},
               {"noise_mm", o.sampling.noise_mm},
               {"outlier_fraction", o.sampling.outlier_fraction},
               {"coverage", o.sampling.half_coverage ? "half" : "full"},
               {"stretch", d.stretch},
               {"bend_mm", d.bend_mm},
               {"twist_rad", d.twist_rad},
               {"indent_mm", d.indent_mm},
               {"push_mm", d.push_mm},
               {"target_shape", r.truth_shape.kind_name()},
               {"target_size_mm",
                {r.truth_shape.size_mm.x(), r.truth_shape.size_mm.y(), r.truth_shape.size_mm.z()}}};
  return r;
}

geometry::Aabb deformed_bounds(const geometry::Shape& s, const evaluation::Deformation& d) {
  const geometry::Aabb b = s.extent();
  geometry::Aabb out =
      geometry::image_of_box(b, [&d](const Eigen::Vector3d& p) { return d.apply(p); });
  // The non-affine parts move points off the corners' hull by at most their amplitudes.
  const double margin = std::abs(d.bend_mm) + std::abs(d.indent_mm) + std::abs(d.push_mm) +
                        std::abs(d.twist_rad) * 0.5 * (b.max_mm - b.min_mm).maxCoeff() +
                        (d.field ? d.field->largest_mm : 0.0);
  out.min_mm.array() -= margin;
  out.max_mm.array() += margin;
  return out;
}

}  // namespace organfit::pipeline
