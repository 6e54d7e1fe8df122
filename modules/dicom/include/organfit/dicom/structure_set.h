#pragma once
// A DICOM RT Structure Set as plain data (apart from its DICOM I/O, as plastimatch keeps
// `rtss` apart from `dcmtk_rtss`), its reading with GDCM, and an ROI rasterised onto a
// CT grid.
#include <array>
#include <filesystem>
#include <string>
#include <vector>

#include "organfit/dicom/ct_series.h"
#include "organfit/geometry/image_geometry.h"
#include "organfit/geometry/slice_contours.h"

namespace organfit::dicom {

struct Contour {
  std::string geometric_type;               ///< CLOSED_PLANAR, OPEN_PLANAR, POINT, ...
  std::string referenced_sop_instance_uid;  ///< the CT slice it lies on (may be absent)
  std::vector<Eigen::Vector3d> points_mm;   ///< patient coordinates
};

struct Roi {
  int number = 0;
  std::string name;
  std::array<int, 3> colour{255, 0, 0};
  std::string frame_of_reference_uid;
  std::vector<Contour> contours;
};

struct StructureSet {
  std::string frame_of_reference_uid;  ///< of the first ROI's reference (all must agree)
  std::vector<Roi> rois;
  const Roi* find(const std::string& name) const;
};

/// Reads an RTSTRUCT file. Throws InputError "FILE: reason" when it cannot be read or
/// is not an RT Structure Set.
StructureSet read_rtstruct(const std::filesystem::path& file);

struct RasterisedRoi {
  geometry::LabelVolume mask;  ///< on the CT's grid, label 1 inside
  int contours = 0;
  int matched_by_position = 0;  ///< contours whose referenced slice is not in the CT
  std::vector<std::string> warnings;
};

/// The ROI `name` rasterised onto the CT grid: per slice, the even-odd rule over all of
/// that slice's contours (islands and holes), voxel centres inside. A contour whose
/// referenced SOP Instance UID is not a slice of the CT is matched to the slice at its
/// position (within a tenth of the slice gap), with a warning. Throws InputError naming
/// `source` on: no such ROI (the names are listed), another Frame of Reference, a contour
/// that is open or has fewer than 3 points, or that lies on no slice or outside the image.
RasterisedRoi rasterise_roi(const StructureSet& rtss, const std::string& name, const CtSeries& ct,
                            const std::string& source);

/// An ROI's contours placed on the CT's slices (for copying them into a structure set we
/// write): each CLOSED_PLANAR contour on the slice its reference names, or, when that is
/// not a slice of the CT, on the slice at its position (as rasterise_roi does). Contours
/// of other types or on no slice are skipped and counted.
struct RoiOnSlices {
  std::vector<geometry::SliceContour> contours;
  int skipped = 0;
  int matched_by_position = 0;
};
RoiOnSlices roi_on_slices(const Roi& roi, const CtSeries& ct);

}  // namespace organfit::dicom
