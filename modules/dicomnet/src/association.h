#pragma once
// One association with a node through DCMTK's DcmSCU, with every failure turned into one
// NodeError line naming the node ("AET@host:port: ..."). Private to dicomnet.
#include <dcmtk/config/osconfig.h>  // must come first
#include <dcmtk/dcmnet/scu.h>

#include <memory>
#include <string>
#include <vector>

#include "organfit/dicomnet/node.h"

namespace organfit::dicomnet::detail {

/// Uncompressed transfer syntaxes, explicit VR little endian first.
std::vector<std::string> uncompressed_transfer_syntaxes();

class Association {
 public:
  /// `scu`: a DcmSCU subclass handling incoming objects (C-GET), or null for a plain one.
  Association(const Node& node, const NetworkOptions& options,
              std::unique_ptr<DcmSCU> scu = nullptr);
  ~Association();  // releases (or aborts) an open association
  Association(const Association&) = delete;
  Association& operator=(const Association&) = delete;

  /// Proposes `sop_class` in `transfer_syntaxes`; `role` ASC_SC_ROLE_SCP for the
  /// storage classes a C-GET brings back.
  void propose(const std::string& sop_class, const std::vector<std::string>& transfer_syntaxes,
               T_ASC_SC_ROLE role = ASC_SC_ROLE_DEFAULT);
  /// Connects and negotiates; NodeError on any failure.
  void open();
  /// The accepted presentation context of `sop_class` (any transfer syntax, or
  /// `transfer_syntax` when given); NodeError "... does not accept <service>" when none.
  T_ASC_PresentationContextID context(const std::string& sop_class, const std::string& service,
                                      const std::string& transfer_syntax = "");
  /// Throws NodeError "<node>: <doing>: <why>" when `cond` is bad.
  void check(const OFCondition& cond, const std::string& doing) const;
  /// "AET@host:port: <message>" as a NodeError.
  [[noreturn]] void fail(const std::string& message) const;

  DcmSCU& scu() { return *scu_; }
  const Node& node() const { return node_; }

 private:
  Node node_;
  NetworkOptions options_;
  std::unique_ptr<DcmSCU> scu_;
};

/// The DIMSE status word as text: "0xA700 (refused: out of resources)".
std::string status_text(Uint16 status);
/// A DICOM status that is a success or a warning (the operation was done).
bool status_done(Uint16 status);

}  // namespace organfit::dicomnet::detail
