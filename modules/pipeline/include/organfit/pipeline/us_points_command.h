#pragma once
// `organfit us-points`: boundary points of an ultrasound input, in CT coordinates, as CSV.
//   a 3D volume (.mha, .mhd, .nrrd, .nii[.gz])          -> rays in 3D from the centre
//   a tracked sweep (sequence metafile with Seq_Frame fields; poses in it or in --tracker)
//   DICOM ultrasound (.dcm; its pixel size from its ultrasound region, or --pixel-mm)
//                                                        -> rays in each frame's plane
// The region of interest is a ball (--centre, --radius) in the output coordinates; by
// default the middle of the image (half depth) and a third of its smaller extent.
#include <filesystem>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

namespace organfit::pipeline {

struct UsPointsCommand {
  std::filesystem::path input, tracker, out;
  std::filesystem::path ct;          ///< the CT the registration maps into: declared in the CSV
  std::vector<double> calibration;   ///< 16 numbers, row-major: image (mm) -> probe
  std::vector<double> registration;  ///< 16 numbers, row-major: tracker/volume -> CT (rigid)
  std::string transform;             ///< tracked transform name (default: the file's own)
  double pixel_mm = 0;               ///< DICOM without a calibrated region
  std::vector<double> centre_mm;     ///< x,y,z
  double radius_mm = 0;              ///< 0: a third of the image's smaller extent
  int count = 87, rays = 2000;
};

/// Runs it; returns the summary printed as JSON. Throws InputError on bad input and
/// TargetNotMetError when no boundary point is found (nothing written then).
nlohmann::json run_us_points(const UsPointsCommand& command);

}  // namespace organfit::pipeline
