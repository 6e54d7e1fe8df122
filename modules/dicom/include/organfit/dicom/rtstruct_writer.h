#pragma once
// Writing a DICOM RT Structure Set that references a planning CT (plain GDCM).
#include <array>
#include <filesystem>
#include <string>
#include <vector>

#include "organfit/dicom/ct_series.h"
#include "organfit/geometry/slice_contours.h"

namespace organfit::dicom {

struct RtstructRoi {
  std::string name;  ///< e.g. Prostate_fit
  std::array<int, 3> colour{255, 128, 0};
  std::vector<geometry::SliceContour> contours;  ///< on the CT's slices (k indexes ct.slices)
  std::string interpreted_type = "ORGAN";  ///< RT ROI Interpreted Type: ORGAN, EXTERNAL, GTV, ...
  std::string generation_algorithm =
      "AUTOMATIC";  ///< ROI Generation Algorithm (empty: unknown, e.g. copied)
};

struct RtstructWriteOptions {
  std::string label = "organfit";                                 ///< Structure Set Label
  std::string series_description = "organfit fitted structures";  ///< (0008,103E)
  /// Deterministic UIDs and dates (for tests): UIDs derived from the CT's and the ROI
  /// names, dates fixed. Otherwise new UIDs under one root per run and today's date.
  bool fixed_uids_and_dates = false;
};

/// Writes the structure set: Patient and Study attributes copied from the CT, the Frame
/// of Reference (top level and referenced), the CT series with a Contour Image Sequence
/// listing its slices, one Structure Set ROI and ROI Contour per ROI (generation
/// AUTOMATIC), CLOSED_PLANAR contours each referencing its slice's SOP Instance UID, and
/// RT ROI Observations. Explicit VR Little Endian. Written under a temporary name and
/// renamed. Throws InputError naming the file when it cannot be written, or when a
/// contour is not on a slice of the CT.
void write_rtstruct(const std::filesystem::path& file, const CtSeries& ct,
                    const std::vector<RtstructRoi>& rois, const RtstructWriteOptions& options = {});

}  // namespace organfit::dicom
