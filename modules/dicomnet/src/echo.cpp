#include "organfit/dicomnet/echo.h"

#include <dcmtk/config/osconfig.h>
#include <dcmtk/dcmdata/dcuid.h>

#include "association.h"
#include "organfit/support/resources.h"

namespace organfit::dicomnet {

double echo(const Node& node, const NetworkOptions& options) {
  const Stopwatch clock;
  detail::Association a(node, options);
  a.propose(UID_VerificationSOPClass, detail::uncompressed_transfer_syntaxes());
  a.open();
  a.check(a.scu().sendECHORequest(a.context(UID_VerificationSOPClass, "C-ECHO")), "C-ECHO");
  return clock.elapsed_s();
}

}  // namespace organfit::dicomnet
