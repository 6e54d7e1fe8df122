#pragma once
// C-FIND: the series a DICOM node holds for a patient or a study (Study Root
// Query/Retrieve Information Model: a STUDY-level query for a patient's studies, then a
// SERIES-level query in each).
#include <string>
#include <vector>

#include "organfit/dicomnet/node.h"

namespace organfit::dicomnet {

/// What to look for. patient_id or study_uid must be given; the others narrow it.
struct SeriesQuery {
  std::string patient_id;  ///< Patient ID (0010,0020): every study of the patient
  std::string study_uid;   ///< Study Instance UID (0020,000D): that study alone
  std::string series_uid;  ///< Series Instance UID (0020,000E): that series alone
  std::string modality;    ///< "CT", "RTSTRUCT", ...: series of that modality alone
};

/// One series as the node describes it (no patient name or ID: they are never logged).
struct SeriesEntry {
  std::string study_uid, series_uid;
  std::string modality;            ///< (0008,0060)
  std::string series_description;  ///< (0008,103E), may be empty
  std::string study_date;          ///< (0008,0020) YYYYMMDD, may be empty
  int series_number = 0;           ///< (0020,0011), 0 when absent
  int instances = -1;  ///< Number of Series Related Instances (0020,1209); -1 when not given

  /// "UID (CT 'Planning CT', 20240102, 120 images)", for listings and messages.
  std::string text() const;
};

/// The series matching `query`, by study date then series number. Throws InputError when
/// the query names neither a patient ID nor a study, NodeError on a network failure or an
/// error status.
std::vector<SeriesEntry> find_series(const Node& node, const NetworkOptions& options,
                                     const SeriesQuery& query);

/// The one series of `found` (find_series' answer to `query`): InputError "<what>: ..."
/// when there is none (the study or series is not there) or several (each listed, to be
/// named with `series_key`).
SeriesEntry choose_series(const std::vector<SeriesEntry>& found, const SeriesQuery& query,
                          const std::string& what, const std::string& series_key);

}  // namespace organfit::dicomnet
