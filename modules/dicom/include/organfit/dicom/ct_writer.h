#pragma once
// Writing a CT series as DICOM (plain GDCM): for synthetic phantoms, whose tests need
// the same files a scanner would give.
#include <filesystem>
#include <string>

#include "organfit/dicom/ct_series.h"

namespace organfit::dicom {

struct CtWriteOptions {
  /// Deterministic UIDs and dates: every UID derived from `uid_key`, dates 20000101.
  /// Otherwise new UIDs under one root and today's date.
  bool fixed_uids_and_dates = false;
  std::string uid_key = "organfit";
  std::string body_part_examined;  ///< e.g. PELVIS (an unpaired part: no Laterality needed)
};

/// Writes `ct.hu` on `ct.geometry` into `folder` (which must not exist yet) as a CT
/// Image Storage series, one file per k slice (`CT0001.dcm`, ...): Patient and Study
/// attributes from `ct.patient`, Image Position and Orientation from the geometry, 12-bit
/// unsigned pixels with Rescale Intercept -1024 (HU outside [-1024, 3071] are clipped and
/// counted in the return value), Explicit VR Little Endian. The folder appears whole or
/// not at all. Empty UIDs in `ct` (study, series, frame of reference) are filled in, and
/// `ct.slices` is set to the files written. Throws InputError naming the folder.
long long write_ct_series(const std::filesystem::path& folder, CtSeries& ct,
                          const CtWriteOptions& options = {});

}  // namespace organfit::dicom
