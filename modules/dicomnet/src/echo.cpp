#include "organfit/dicomnet/echo.h"

#include <dcmtk/config/osconfig.h>
#include <dcmtk/dcmdata/dcuid.h>

#include <chrono>

#include "association.h"

namespace organfit::dicomnet {

double echo(const Node& node, const NetworkOptions& options) {
  const auto start = std::chrono::steady_clock::now();
  detail::Association a(node, options);
  a.propose(UID_VerificationSOPClass, detail::uncompressed_transfer_syntaxes());
  a.open();
  a.check(a.scu().sendECHORequest(a.context(UID_VerificationSOPClass, "C-ECHO")), "C-ECHO");
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
}

}  // namespace organfit::dicomnet
