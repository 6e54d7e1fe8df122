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
  /// As read: Number of Contour Points (-1 when absent) and the count of Contour Data
  /// values, which must be three times it (checked where the contour is used).
  long declared_points = -1;
  long value_count = 0;
};

struct Roi {
  int number = 0;
  std::string name;
  std::array<int, 3> colour{255, 0, 0};  ///< ROI Display Color (red when absent)
  std::string interpreted_type;  ///< RT ROI Interpreted Type (ORGAN, GTV, ...; may be empty)
  std::string frame_of_reference_uid;
  std::vector<Contour> contours;
};

struct StructureSet {
  std::string frame_of_reference_uid;  ///< of the first ROI's reference (all must agree)
  /// The Frame of Reference the set declares in its Referenced Frame of Reference Sequence
  /// (3006,0010), used for an ROI that names none itself.
  std::string referenced_frame_of_reference_uid;
  /// The CT series the set declares it was drawn on (RT Referenced Series in 3006,0010):
  /// the one chosen when a folder holds several and none is named.
  std::vector<std::string> referenced_series_uids;
  /// Whose it is, to check it against the CT. Never logged.
  std::string patient_id, study_instance_uid;
  std::vector<Roi> rois;
  /// The first ROI of that name (nullptr when none); see rois_named for duplicates.
  const Roi* find(const std::string& name) const;
  std::vector<const Roi*> rois_named(const std::string& name) const;
  const Roi* find_number(int number) const;
};

/// Reads an RTSTRUCT file. Throws InputError "FILE: reason" when it cannot be read or
/// is not an RT Structure Set.
StructureSet read_rtstruct(const std::filesystem::path& file);

struct RasterisedRoi {
  geometry::LabelVolume mask;  ///< on the CT's grid, label 1 inside
  int contours = 0;
  int matched_by_position = 0;           ///< contours whose referenced slice is not in the CT
  int skipped = 0;                       ///< degenerate contours (fewer than 3 points, zero area)
  std::array<int, 3> colour{255, 0, 0};  ///< the ROI's display colour
  std::string interpreted_type;          ///< the ROI's RT ROI Interpreted Type (may be empty)
  std::vector<std::string> warnings;
};

/// How far (in slice gaps) a contour may lie from the slice it is matched to, by
/// reference or by position: a tenth of the gap.
constexpr double kContourSliceTolerance = 0.1;

/// Refuses a structure set that is not of this CT, with an InputError naming `source`,
/// the CT's folder and the attribute (never the patient's values): another Patient ID or
/// Study Instance UID (compared when both are given), `roi` in another Frame of Reference,
/// or no Frame of Reference at all while some contour of `roi` references no slice of the
/// CT.
void check_structure_set_matches_ct(const StructureSet& rtss, const Roi& roi, const CtSeries& ct,
                                    const std::string& source);

/// The ROI to import: by name, or by ROI Number when `roi_number` > 0 (then `name`, when
/// given, must be its name). Throws InputError naming `source` when there is none, or
/// when several ROIs carry the name and no number chooses (their numbers are listed).
const Roi& choose_roi(const StructureSet& rtss, const std::string& name, int roi_number,
                      const std::string& source);

/// The ROI `name` (or number `roi_number`, see choose_roi) rasterised onto the CT grid:
/// per slice, the even-odd rule over all of that slice's contours (islands and holes),
/// voxel centres inside. A contour is placed on the slice its Referenced SOP Instance UID
/// names when it lies within kContourSliceTolerance of it; else (no reference, a slice
/// not in this series, or a reference its z contradicts) on the slice at its position,
/// with a warning. A contour of fewer than 3 points or of zero area is skipped with a
/// warning naming its slice. Throws InputError naming `source` on: a structure set not of
/// this CT (check_structure_set_matches_ct), a contour that is open, whose Contour Data
/// has not 3 x Number of Contour Points values, that lies on no slice or outside the image.
RasterisedRoi rasterise_roi(const StructureSet& rtss, const std::string& name, const CtSeries& ct,
                            const std::string& source, int roi_number = 0);

/// An ROI's contours placed on the CT's slices (for copying them into a structure set we
/// write), each on its slice as rasterise_roi places it. Contours of other types, of fewer
/// than 3 points or zero area, with a wrong value count or on no slice are skipped and
/// counted.
struct RoiOnSlices {
  std::vector<geometry::SliceContour> contours;
  int skipped = 0;
  int matched_by_position = 0;
};
RoiOnSlices roi_on_slices(const Roi& roi, const CtSeries& ct);

}  // namespace organfit::dicom
