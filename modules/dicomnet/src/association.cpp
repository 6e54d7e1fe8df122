#include "association.h"

#include <dcmtk/dcmdata/dcuid.h>
#include <dcmtk/dcmnet/diutil.h>
#include <dcmtk/oflog/oflog.h>
#include <fmt/format.h>

#include <cmath>
#include <csignal>
#include <cstdlib>
#include <mutex>

namespace organfit::dicomnet::detail {
namespace {

/// DCMTK logs to stderr by itself; organfit's errors are one line of its own.
void quiet_dcmtk() {
  static std::once_flag once;
  std::call_once(once, [] {
    OFLog::configure(OFLogger::OFF_LOG_LEVEL);
    // A node closing the connection mid-write must be an error, not the end of the process.
    std::signal(SIGPIPE, SIG_IGN);
    // Debian's DCMTK leaves Nagle's algorithm on unless TCP_NODELAY is set: each small
    // DIMSE message then waits for the peer's delayed ACK (measured against Orthanc: a
    // 56-slice C-GET in 5.0 s, 2.5 s with it off on our side). A user's own setting stays.
    setenv("TCP_NODELAY", "1", /*overwrite=*/0);
  });
}

/// What a DCMTK condition says, without DCMTK's module prefix.
std::string reason_of(const OFCondition& cond) {
  std::string text = cond.text();
  // "TCP Initialization Error: Connection refused" -> "Connection refused"
  if (const auto colon = text.rfind(": ");
      colon != std::string::npos && cond.module() == OFM_dcmnet)
    text = text.substr(colon + 2);
  return text;
}

}  // namespace

std::vector<std::string> uncompressed_transfer_syntaxes() {
  return {UID_LittleEndianExplicitTransferSyntax, UID_LittleEndianImplicitTransferSyntax};
}

Association::Association(const Node& node, const NetworkOptions& options,
                         std::unique_ptr<DcmSCU> scu)
    : node_(node), options_(options), scu_(scu ? std::move(scu) : std::make_unique<DcmSCU>()) {
  quiet_dcmtk();
  const auto seconds = static_cast<Uint32>(std::max(1.0, std::ceil(options.timeout_s)));
  scu_->setAETitle(options.calling_aet.c_str());
  scu_->setPeerAETitle(node.aet.c_str());
  scu_->setPeerHostName(node.host.c_str());
  scu_->setPeerPort(static_cast<Uint16>(node.port));
  scu_->setConnectionTimeout(static_cast<Sint32>(seconds));
  scu_->setACSETimeout(seconds);
  scu_->setDIMSETimeout(seconds);
  scu_->setDIMSEBlockingMode(DIMSE_NONBLOCKING);  // the DIMSE timeout applies
}

Association::~Association() {
  if (scu_ && scu_->isConnected()) {
    if (scu_->releaseAssociation().bad()) scu_->abortAssociation();
  }
}

void Association::propose(const std::string& sop_class,
                          const std::vector<std::string>& transfer_syntaxes, T_ASC_SC_ROLE role) {
  OFList<OFString> ts;
  for (const auto& t : transfer_syntaxes)
    ts.push_back(t.c_str());
  check(scu_->addPresentationContext(sop_class.c_str(), ts, role), "proposing a service");
}

void Association::open() {
  check(scu_->initNetwork(), "starting the network");
  const OFCondition cond = scu_->negotiateAssociation();
  if (cond.good()) return;
  if (cond == DUL_ASSOCIATIONREJECTED)
    fail(
        fmt::format("refused the association: check the node's AE title ('{}') and that the "
                    "node knows ours ('{}')",
                    organfit::echo(node_.aet), organfit::echo(options_.calling_aet)));
  if (cond == NET_EC_NoAcceptablePresentationContexts)
    fail("accepted the association but none of the services asked for");
  if (cond == DUL_READTIMEOUT || cond == DIMSE_NODATAAVAILABLE)
    fail(fmt::format("did not answer within {:g} s (network.timeout_s)", options_.timeout_s));
  const std::string why = reason_of(cond);
  if (why.find("timeout") != std::string::npos || why.find("timed out") != std::string::npos)
    fail(fmt::format("cannot connect within {:g} s (network.timeout_s): {}", options_.timeout_s,
                     why));
  fail("cannot connect: " + why);
}

T_ASC_PresentationContextID Association::context(const std::string& sop_class,
                                                 const std::string& service,
                                                 const std::string& transfer_syntax) {
  const T_ASC_PresentationContextID id =
      transfer_syntax.empty()
          ? scu_->findAnyPresentationContextID(sop_class.c_str(), "")
          : scu_->findPresentationContextID(sop_class.c_str(), transfer_syntax.c_str());
  if (id == 0) fail("does not accept " + service);
  return id;
}

void Association::check(const OFCondition& cond, const std::string& doing) const {
  if (cond.good()) return;
  if (cond == DUL_READTIMEOUT || cond == DIMSE_NODATAAVAILABLE)
    fail(fmt::format("{}: no answer within {:g} s (network.timeout_s)", doing, options_.timeout_s));
  if (cond == DUL_PEERABORTEDASSOCIATION || cond == DUL_PEERREQUESTEDRELEASE ||
      cond == DUL_NETWORKCLOSED)
    fail(
        fmt::format("{}: the node closed the association (does it let our AE title '{}' do "
                    "this?)",
                    doing, organfit::echo(options_.calling_aet)));
  fail(doing + ": " + reason_of(cond));
}

void Association::fail(const std::string& message) const {
  throw NodeError(node_.text() + ": " + message);
}

std::string status_text(Uint16 status) {
  const char* meaning = "";
  if (status == 0x0000)
    meaning = "success";
  else if (status == 0xFE00)
    meaning = "cancelled";
  else if (status == 0x0122 || status == 0x0124 || status == 0xA900 || status == 0x0117)
    meaning = "refused: SOP class not supported, not authorised or data set does not match";
  else if ((status & 0xFF00) == 0xA700)
    meaning = "refused: out of resources";
  else if ((status & 0xFF00) == 0xA800)
    meaning = "refused: move destination unknown";
  else if ((status & 0xF000) == 0xC000)
    meaning = "failed: unable to process";
  else if ((status & 0xF000) == 0xB000)
    meaning = "warning: some sub-operations failed or elements were coerced";
  else if ((status & 0xF000) == 0xA000)
    meaning = "failed";
  return meaning[0] ? fmt::format("0x{:04X} ({})", status, meaning)
                    : fmt::format("0x{:04X}", status);
}

bool status_done(Uint16 status) {
  return status == 0x0000 || (status & 0xF000) == 0xB000 || status == 0x0107 || status == 0x0116;
}

}  // namespace organfit::dicomnet::detail
