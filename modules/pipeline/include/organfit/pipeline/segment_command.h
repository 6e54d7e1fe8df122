#pragma once
// `organfit segment`: an organ mask from a CT, imported from an RT Structure Set or grown
// from a seed, written with the CT's geometry.
#include <Eigen/Core>
#include <filesystem>
#include <string>
#include <vector>

namespace organfit::pipeline {

struct SegmentRequest {
  std::filesystem::path ct_folder;
  std::string series_uid;
  std::filesystem::path rtstruct;  ///< with roi: import
  std::string roi;
  int roi_number = 0;             ///< or by ROI Number (> 0), when names repeat
  std::vector<double> seed_mm;    ///< x,y,z with hu: grow from a seed
  std::vector<double> hu_window;  ///< low,high
  double search_box_mm = 200;     ///< cube around the seed grown in (0: the whole CT)
  std::filesystem::path out;      ///< .nrrd, .mha, .nii(.gz)
};

struct SegmentResult {
  double volume_cm3 = 0;
  std::vector<std::string> warnings;
};

/// Throws InputError on bad input (and writes nothing then).
SegmentResult run_segment(const SegmentRequest& request);

}  // namespace organfit::pipeline
