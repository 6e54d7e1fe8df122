#pragma once
// Reading a planning CT series from a folder (GDCM), into plain types.
//
// The folder may hold several series and other objects (RTSTRUCT, RTDOSE, stray
// files): the CT is picked by Modality, and by Series Instance UID or description when
// there are several. Slices are sorted along the slice normal. Geometry is kept in
// patient coordinates (DICOM LPS, mm) with its direction matrix:
//   i (columns) along the first three Image Orientation cosines, spacing PixelSpacing[1];
//   j (rows) along the last three, spacing PixelSpacing[0]; k along the normal.
// Values are Hounsfield units: stored value * Rescale Slope + Rescale Intercept.
//
// Refused with a one-line InputError naming the folder and the defect: no CT, several
// CT series and no choice, a missing slice, duplicate slice positions, irregular slice
// spacing, gantry tilt, non-axial slices, slices whose size, pixel spacing or orientation
// differ. Tolerated with a warning: files that are not DICOM, other modalities.
#include <filesystem>
#include <memory>
#include <string>
#include <vector>

#include "organfit/geometry/image_geometry.h"

namespace organfit::dicom {

/// Who and what the CT belongs to, copied into exported objects. Never logged.
/// The Patient, Patient Study, Clinical Trial Subject and General Study attributes of a
/// CT that PatientStudy does not name (age, weight, Patient Identity Removed,
/// De-identification Method and its code sequence, physicians of record, ...), as read:
/// the exported objects copy them so that they agree with the CT (dcentvfy). Opaque to
/// the rest of organfit (this module's GDCM data set).
struct CopiedModules;

struct PatientStudy {
  std::string patient_name, patient_id, patient_birth_date, patient_sex;
  std::string study_instance_uid, study_id, study_date, study_time, study_description;
  std::string accession_number, referring_physician_name;
  /// The text above is UTF-8 (converted from the source's character set), unless this
  /// holds the source's Specific Character Set (one with ISO 2022 code extensions, whose
  /// bytes are kept as they are): exported objects then declare it.
  std::string specific_character_set;
  std::shared_ptr<const CopiedModules> other_attributes;  ///< null: none read
};

struct CtSlice {
  std::string sop_instance_uid;
  std::string sop_class_uid;
  Eigen::Vector3d position_mm;  ///< Image Position (Patient)
  std::filesystem::path file;
};

struct CtSeries {
  std::filesystem::path folder;  ///< where it was read from (for messages)
  geometry::ImageGeometry geometry;
  std::vector<float> hu;  ///< geometry.voxel_count() values, i fastest
  std::string series_instance_uid, series_description, frame_of_reference_uid;
  PatientStudy patient;
  std::vector<CtSlice> slices;        ///< in k order
  std::vector<std::string> warnings;  ///< tolerated defects, one line each
  /// Which series was read and why, when the folder holds several and none was named (an
  /// info line: "series 'X' (48 slices) read: the series the structure set references, of
  /// 2 CT series"; empty when it was named or the only one).
  std::string choice;
};

struct CtReadOptions {
  std::string series_instance_uid;  ///< choose this series (empty: the only CT one)
  std::string series_description;   ///< or the one with this description
  /// Neither given and the folder holds several series: the one of these there is, when
  /// there is exactly one (the series a structure set was drawn on, or a planning model
  /// built on).
  std::vector<std::string> referenced_series_uids;
  std::string referenced_by = "the structure set";  ///< what references them, for messages
  double spacing_tolerance = 0.02;  ///< relative deviation of slice gaps still regular
};

/// Reads the CT series in `folder`. Throws InputError "FOLDER: reason" on bad input.
CtSeries read_ct_series(const std::filesystem::path& folder, const CtReadOptions& options = {});

}  // namespace organfit::dicom
