#pragma once
// A DICOM node (a PACS, a treatment planning system) as organfit talks to it, and the
// error a node's failure raises.
//
// A node is written AET@host:port, as plastimatch and most DICOM tools' documentation
// write it: the node's own (called) AE title, its host name or address, its TCP port.
#include <string>

#include "organfit/support/error.h"

namespace organfit::dicomnet {

/// Where a DICOM node listens and the AE title it answers to.
struct Node {
  std::string aet;   ///< the node's (called) AE title: 1-16 characters, no backslash
  std::string host;  ///< host name or address
  int port = 104;    ///< TCP port, 1-65535

  /// "AET@host:port", for messages.
  std::string text() const;
};

/// Our side of an association.
struct NetworkOptions {
  std::string calling_aet = "ORGANFIT";  ///< our own AE title, as the node knows us
  double timeout_s = 30;  ///< connecting, association and each message: longer is a failure
};

/// Parses "AET@host:port". InputError "<what>: ..." when malformed: no '@' or ':', an
/// empty or over-long AE title, a port outside 1-65535.
Node parse_node(const std::string& text, const std::string& what);

/// Checks an AE title of our own (1-16 characters of the default repertoire, no
/// backslash, not all spaces). InputError "<what>: ..." when not.
void check_ae_title(const std::string& aet, const std::string& what);

/// A node that could not be reached, refused the association, did not answer in time or
/// answered with an error status. Exit 2, like any input that cannot be used.
class NodeError : public Error {
 public:
  explicit NodeError(const std::string& message) : Error(ExitCode::kBadInput, message) {}
};

}  // namespace organfit::dicomnet
