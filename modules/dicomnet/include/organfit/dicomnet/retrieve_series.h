#pragma once
// C-GET: one series copied from a DICOM node into a local folder.
//
// C-GET rather than C-MOVE: the objects come back on the association organfit opened,
// so organfit needs no listening port, no firewall opening and no entry as a move
// destination in the node's configuration; the node only has to allow our AE title to
// retrieve (Orthanc: DicomModalities, or DicomAlwaysAllowGet).
#include <filesystem>
#include <string>
#include <vector>

#include "organfit/dicomnet/node.h"

namespace organfit::dicomnet {

/// What a retrieval wrote.
struct RetrievedSeries {
  std::vector<std::filesystem::path> files;  ///< one per instance: <SOP Instance UID>.dcm
  double wall_s = 0;                         ///< the whole exchange
};

/// Retrieves every instance of series `series_uid` of study `study_uid` into `folder`
/// (created; existing files of the same names are replaced), each file written whole
/// or not at all. Accepts CT, MR, US, RT Structure Set and registration objects, in
/// uncompressed or lossless transfer syntaxes. NodeError when the node fails, answers
/// with an error status, reports failed sub-operations or sends nothing (the series does
/// not exist there).
RetrievedSeries retrieve_series(const Node& node, const NetworkOptions& options,
                                const std::string& study_uid, const std::string& series_uid,
                                const std::filesystem::path& folder);

}  // namespace organfit::dicomnet
