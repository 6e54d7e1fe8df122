#include "organfit/support/error.h"

namespace organfit {

ExitCode exit_code_of(const std::exception& e) {
  if (const auto* err = dynamic_cast<const Error*>(&e)) return err->code();
  return ExitCode::kInternal;
}

}  // namespace organfit
