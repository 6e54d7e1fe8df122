#pragma once
// The points stage: the attractive points of a run, generated on the model's shape (or
// another of its volume) under a known deformation (points.source: generate), or read
// from a file (points.source: file: a table, or a mesh's vertices).
#include <filesystem>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <vector>

#include "organfit/config/scene.h"
#include "organfit/evaluation/synthetic.h"
#include "organfit/fitting/attractive_points.h"
#include "organfit/geometry/shape.h"
#include "organfit/pipeline/model_stage.h"
#include "organfit/pipeline/points_file.h"

namespace organfit::pipeline {

struct PointsStageResult {
  std::vector<fitting::AttractivePoint> points;
  std::optional<evaluation::Deformation> truth;  ///< set when the points were generated
  geometry::Shape truth_shape;                   ///< the shape they were sampled on
  PointsCt declared_ct;                          ///< the CT a points file declares
  nlohmann::json summary;
  std::vector<std::string> warnings;  ///< what the user should know about the points read
};

/// A point set by extension: a table (read_points_table, with the CT it declares), or the
/// vertices of a .ply, .vtk or .vtp. Throws InputError naming the file on bad content or
/// no points.
PointsTable read_points_file(const std::filesystem::path& file);

/// Drops every point at exactly the position (the same coordinates, as read) of an earlier
/// one, keeping the first of each position in the file's order, and returns how many were
/// dropped. One position read twice is one observation: counted twice, the fit would take
/// it for more evidence than it is (87 copies of one point were fitted as 87 points, their
/// uncertainty as if 87 places had been seen).
size_t drop_repeated_points(std::vector<fitting::AttractivePoint>& points);

/// Refuses points that look written in centimetres or metres instead of mm (DICOM's
/// patient coordinates): throws InputError naming `file` when, of the points as given and
/// scaled by 10 and by 1000 about the patient origin, a scaled set lies nearest the planning
/// organ's surface (median distances), nearer than halfway to the organ's middle (a quarter
/// of its box's smallest side). Why: where the organ lies within the global fit's reach of
/// the origin (fit.spread.max_global_shift_mm; planning CTs often put the origin near the
/// target), a centimetre point set lies inside it, and a fit moves the organ onto it and
/// converges. Points in mm never pass: scaling moves a point 9 (999) times its distance from
/// the origin, which takes points spread over a surface off it by about the organ's size or
/// more; points at no unit's scale (a cluster in the organ's middle) lie as far from the
/// surface at each of the three scales.
void check_points_unit(const std::vector<fitting::AttractivePoint>& points,
                       const fitting::OrganModel& model, const std::filesystem::path& file);

/// What the points section asks for (its keys; units and docs in scene_schema.cpp).
struct PointsOptions {
  std::string source = "generate";  ///< generate, file (ultrasound: the ultrasound stage's)
  std::filesystem::path file;       ///< source: file
  /// source: generate: the true deformation's parameters (its centre and length are the
  /// shape's, set by deformation_about), the sampling (count, noise, outliers, half
  /// coverage, seed), and the shape sampled ("same": the model's; else a shape of its
  /// volume, of target_size_mm's proportions).
  evaluation::Deformation deformation;
  evaluation::SamplingOptions sampling;
  std::string target_shape = "same";
  Eigen::Vector3d target_size_mm = Eigen::Vector3d(40, 30, 60);
};
PointsOptions points_options_from(const config::Scene& scene);

PointsStageResult run_points_stage(const PointsOptions& options, const ModelStageResult& model);

/// `d` about the shape: centred on its centre, its half length along x the shape's x half size
/// times the stretch.
evaluation::Deformation deformation_about(evaluation::Deformation d, const geometry::Shape& shape);
/// The true deformation the points section describes (evaluation::Deformation), not yet
/// placed about a shape (deformation_about).
evaluation::Deformation true_deformation_from(const config::Scene& scene);

/// A box holding the deformed shape: its extent()'s corners mapped, widened by the
/// non-affine parts.
geometry::Aabb deformed_bounds(const geometry::Shape& shape,
                               const evaluation::Deformation& deformation);

}  // namespace organfit::pipeline
