#include "organfit/support/error.h"

#include <sys/resource.h>

#include <cstdio>
#include <new>

namespace organfit {

std::string echo(const std::string& value, size_t max_chars) {
  std::string out;
  size_t chars = 0;
  for (size_t i = 0; i < value.size();) {
    if (chars == max_chars) return out + "...";
    ++chars;
    const auto c = static_cast<unsigned char>(value[i]);
    // A UTF-8 character's length from its lead byte; a byte that starts none, or a
    // sequence cut short, is one '?' (a file's bytes echoed raw can garble a terminal).
    const size_t length = c < 0x80             ? 1
                          : (c & 0xE0) == 0xC0 ? 2
                          : (c & 0xF0) == 0xE0 ? 3
                          : (c & 0xF8) == 0xF0 ? 4
                                               : 0;
    bool whole = length > 0 && i + length <= value.size();
    for (size_t k = 1; whole && k < length; ++k)
      whole = (static_cast<unsigned char>(value[i + k]) & 0xC0) == 0x80;
    if (!whole) {
      out += '?';
      ++i;
    } else if (length == 1) {
      out += (c < 0x20 || c == 0x7f) ? '?' : value[i];
      ++i;
    } else {
      out.append(value, i, length);
      i += length;
    }
  }
  return out;
}

long long address_space_limit_mb() {
  rlimit limit{};
  if (::getrlimit(RLIMIT_AS, &limit) != 0 || limit.rlim_cur == RLIM_INFINITY) return -1;
  return static_cast<long long>(limit.rlim_cur >> 20);
}

const char* out_of_memory_message() {
  // Into a buffer of its own: no memory is asked for while there is none.
  static char text[256];
  if (const long long mb = address_space_limit_mb(); mb >= 0)
    std::snprintf(text, sizeof text,
                  "out of memory: the run needed more than this process may use (its address "
                  "space is limited to %lld MB: ulimit -v); nothing was written",
                  mb);
  else
    std::snprintf(text, sizeof text,
                  "out of memory: the run needed more than the machine had free; nothing was "
                  "written");
  return text;
}

ExitCode exit_code_of(const std::exception& e) {
  if (const auto* err = dynamic_cast<const Error*>(&e)) return err->code();
  if (dynamic_cast<const std::bad_alloc*>(&e)) return ExitCode::kBadInput;
  return ExitCode::kInternal;
}

}  // namespace organfit
