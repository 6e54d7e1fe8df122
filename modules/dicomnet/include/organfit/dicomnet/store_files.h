#pragma once
// C-STORE: DICOM files sent to a node (a planning system, a PACS).
#include <filesystem>
#include <vector>

#include "organfit/dicomnet/node.h"

namespace organfit::dicomnet {

/// What a send did.
struct StoredFiles {
  int sent = 0;      ///< files the node accepted (warning statuses included)
  int warnings = 0;  ///< of those, accepted with a warning status (e.g. coerced elements)
  double wall_s = 0;
};

/// Sends each of `files` (DICOM Part 10 files) over one association, in its own transfer
/// syntax or an uncompressed one the node accepts. NodeError naming the file and the
/// status when the node refuses one (the files after it are not sent), and on a network
/// failure; InputError when a file is not a readable DICOM file.
StoredFiles store_files(const Node& node, const NetworkOptions& options,
                        const std::vector<std::filesystem::path>& files);

}  // namespace organfit::dicomnet
