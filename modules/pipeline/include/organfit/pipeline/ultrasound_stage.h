#pragma once
// The ultrasound stage: attractive points segmented from an ultrasound volume, either
// simulated from the planning CT deformed by a known map (ground truth), or read.
#include <filesystem>
#include <optional>
#include <string>

#include "organfit/config/scene.h"
#include "organfit/dicom/ct_series.h"
#include "organfit/pipeline/points_stage.h"
#include "organfit/pipeline/ultrasound_defaults.h"
#include "organfit/ultrasound/boundary_points.h"
#include "organfit/ultrasound/simulator.h"

namespace organfit::pipeline {

struct UltrasoundStageResult {
  PointsStageResult points;                       ///< truth set when simulated
  std::optional<geometry::LabelVolume> bmode;     ///< the B-mode volume (8 bit), to save if asked
  std::vector<Eigen::Vector3d> true_boundary_mm;  ///< simulated: the surface the probe sees
};

/// Tissue classes of a CT by HU, with the organ on top: what the simulator images.
/// Labels: 1 gas (< -400), 2 fat (< -30), 3 fluid (< 25), 4 soft tissue (< 150),
/// 5 dense (< 400), 6 bone, 7 the organ (mask label 1).
geometry::LabelVolume tissue_classes(const geometry::ImageGeometry& ct,
                                     const std::vector<float>& hu,
                                     const geometry::LabelVolume* organ_mask);

/// The same classes from the pelvis phantom's true labels (no partial-volume voxels:
/// classes from HU put a dark "fluid" rim between the gland and fat, -26 HU being half way).
geometry::LabelVolume pelvis_tissue_classes(const geometry::LabelVolume& phantom_labels);

/// Today's anatomy for the simulator: `organ` deformed by `deformation`, the rest as the
/// planning CT has it (tissue classes and HU on its grid), fat where the organ was.
ultrasound::TissueAt deformed_anatomy(const geometry::LabelVolume& tissue,
                                      const std::vector<float>& hu, const geometry::Shape& organ,
                                      const evaluation::Deformation& deformation);

/// The ultrasound section: where the images come from (ultrasound.source: simulate,
/// volume, sweep, dicom) and how they are placed in the CT, the simulator's settings
/// (simulate), and the boundary search.
struct UltrasoundStageOptions {
  std::string source = "simulate";
  Eigen::Matrix4d registration = Eigen::Matrix4d::Identity();  ///< ultrasound/tracker -> CT
  Eigen::Matrix4d calibration = Eigen::Matrix4d::Identity();   ///< image -> probe (2D frames)
  /// simulate: the true deformation (not yet about the organ), the probe about the organ's
  /// centre (mm; axis and lateral unit vectors) and the simulator's settings
  evaluation::Deformation deformation;
  Eigen::Vector3d probe_offset_mm = Eigen::Vector3d::Zero();
  Eigen::Vector3d probe_axis = Eigen::Vector3d::UnitY(), probe_lateral = Eigen::Vector3d::UnitX();
  ultrasound::SimulatorOptions simulator;
  /// volume, sweep, dicom: the image file (sweep: and its tracker, the transform's name);
  /// dicom: the pixel size when the file has none (mm)
  std::filesystem::path file;
  std::optional<std::filesystem::path> tracker;
  std::string transform;
  double pixel_mm = 0;
  ultrasound::BoundaryOptions boundary;  ///< target_count: points.count
  config::KeyRef source_key, probe_axis_key;
};
UltrasoundStageOptions ultrasound_stage_options_from(const config::Scene& scene);

/// Runs the stage. `ct` and `organ_mask` (on the CT grid) are needed to simulate;
/// `anatomy` (tissue classes on the CT grid, e.g. the phantom's) replaces the classes
/// from HU when given.
UltrasoundStageResult run_ultrasound_stage(const UltrasoundStageOptions& options,
                                           const ModelStageResult& model, const dicom::CtSeries* ct,
                                           const geometry::LabelVolume* organ_mask,
                                           const geometry::LabelVolume* anatomy = nullptr);

/// How far simulated points lie from the true (deformed) surface, against a dense noise-
/// free sampling of it, and the share on the part the probe sees (within 1.5 mm of
/// `true_boundary_mm`): median, p90 and largest distance (mm), shares, into points.summary.
void measure_points_against_truth(PointsStageResult& points,
                                  const std::vector<Eigen::Vector3d>& true_boundary_mm);

}  // namespace organfit::pipeline
