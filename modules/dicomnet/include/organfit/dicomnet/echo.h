#pragma once
// C-ECHO: whether a DICOM node answers (the DICOM "ping").
#include "organfit/dicomnet/node.h"

namespace organfit::dicomnet {

/// Opens an association with `node`, sends one C-ECHO and releases it. Returns the wall
/// time of the whole exchange (s). NodeError when the node cannot be reached, refuses the
/// association, does not answer within options.timeout_s or answers with an error status.
double echo(const Node& node, const NetworkOptions& options);

}  // namespace organfit::dicomnet
