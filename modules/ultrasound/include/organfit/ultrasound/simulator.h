#pragma once
// A B-mode ultrasound simulator for ground truth: what a probe at a known pose would
// image of a labelled body (e.g. the pelvis phantom, deformed by a known map).
//
// Rays leave the probe in a pyramid (lateral and elevational half-angles) starting at
// the probe's surface (the probe displaces the gas of the rectum it sits in) and are
// sampled every `ray_step_mm`. Along each ray, each sample's echo is
//   echogenicity(tissue) x speckle + specular(boundary),
// with Rayleigh-distributed multiplicative speckle (unit mean, drawn from the seed and the
// sample's index), a bright specular line (`specular_mm` deep, centred on the interface)
// where the tissue label changes, exponential
// depth attenuation, and total shadow beyond the first gas (HU < -400) or bone
// (HU > 400) sample, which itself reflects strongly. Echoes are log-compressed to 0..255
// over `dynamic_range_db` and scan-converted onto a Cartesian grid aligned with the CT.
// The true boundary points are where rays enter or leave the organ before any shadow:
// the part of its surface the probe sees.
#include <Eigen/Core>
#include <array>
#include <cstdint>
#include <functional>
#include <vector>

#include "organfit/geometry/image_geometry.h"

namespace organfit::ultrasound {

struct ProbePose {
  Eigen::Vector3d position_mm = Eigen::Vector3d::Zero();  ///< centre of the probe's face (CT mm)
  Eigen::Vector3d axis = Eigen::Vector3d(0, -1, 0);  ///< beam direction at the centre of the field
  Eigen::Vector3d lateral = Eigen::Vector3d(1, 0, 0);  ///< in-plane direction across the image
};

struct SimulatorOptions {
  double probe_radius_mm = 10;  ///< imaging starts this far from the probe's centre
  double max_depth_mm = 70;     ///< from the probe's centre
  double lateral_half_angle_deg = 50, elevation_half_angle_deg = 50;
  int lateral_rays = 161, elevation_rays = 161;
  double ray_step_mm = 0.25;
  double voxel_mm = 0.5;                ///< output grid spacing
  double speckle = 1.0;                 ///< 0: no speckle; 1: fully developed (Rayleigh)
  double specular = 0.8;                ///< brightness added at a tissue boundary
  double specular_mm = 1.0;             ///< thickness of that bright line (axial resolution)
  double attenuation_db_per_mm = 0.05;  ///< after time-gain compensation
  double dynamic_range_db = 50;
  std::array<float, 256> echogenicity;  ///< mean echo per label (0 = anechoic)
  std::uint8_t organ_label = 0;         ///< whose visible boundary is returned as truth
  std::uint64_t seed = 1;
  SimulatorOptions() { echogenicity.fill(0.5f); }
};

struct SimulatedUltrasound {
  geometry::ImageGeometry geometry;               ///< Cartesian, CT axes, voxel_mm
  std::vector<std::uint8_t> bmode;                ///< 0..255, 0 outside the field of view
  std::vector<std::uint8_t> in_view;              ///< 1 inside the field of view
  std::vector<Eigen::Vector3d> true_boundary_mm;  ///< visible organ boundary (CT mm)
};

/// The tissue at a point: its label (-1 outside the body's data) and CT value (HU).
struct TissueSample {
  int label = -1;
  float hu = -1000;
};
using TissueAt = std::function<TissueSample(const Eigen::Vector3d& p_mm)>;

/// Simulates the probe on the anatomy `tissue_at` describes (called from several threads;
/// a continuous description keeps organ boundaries smooth, unlike a CT's 2.5 mm slices).
/// Throws std::invalid_argument on a pose whose axes are not perpendicular, or bad
/// sampling.
SimulatedUltrasound simulate_bmode(const TissueAt& tissue_at, const ProbePose& probe,
                                   const SimulatorOptions& options);

/// The same on labelled voxels (nearest voxel) with their HU (same grid).
SimulatedUltrasound simulate_bmode(const geometry::LabelVolume& labels,
                                   const std::vector<float>& hu, const ProbePose& probe,
                                   const SimulatorOptions& options);

}  // namespace organfit::ultrasound
