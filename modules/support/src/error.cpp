#include "organfit/support/error.h"

namespace organfit {

std::string echo(const std::string& value, size_t max_chars) {
  std::string out;
  size_t chars = 0;
  for (size_t i = 0; i < value.size(); ++i) {
    const auto c = static_cast<unsigned char>(value[i]);
    const bool continuation = (c & 0xC0) == 0x80;
    if (!continuation && chars == max_chars) return out + "...";
    if (!continuation) ++chars;
    out += (c < 0x20 || c == 0x7f) ? '?' : value[i];
  }
  return out;
}

ExitCode exit_code_of(const std::exception& e) {
  if (const auto* err = dynamic_cast<const Error*>(&e)) return err->code();
  return ExitCode::kInternal;
}

}  // namespace organfit
