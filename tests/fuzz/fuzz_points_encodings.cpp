// The point-table reader on arbitrary text in each encoding it accepts: the first byte
// picks the encoding (UTF-8 with its mark, UTF-16 LE or BE with or without a mark) and
// the line ends (LF, CRLF, CR); the rest is the text, so that the fuzzer explores the
// table parsing behind each decoder rather than the decoders' first bytes alone.
#include <string>

#include "fuzz_util.h"
#include "organfit/pipeline/points_file.h"
#include "organfit/support/error.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  if (size == 0) return 0;
  const int encoding = data[0] % 5, line_ends = (data[0] / 5) % 3;
  std::string text;
  for (size_t i = 1; i < size; ++i) {
    const char c = static_cast<char>(data[i]);
    if (c == '\n' && line_ends == 1) text += '\r';
    text += (c == '\n' && line_ends == 2) ? '\r' : c;
  }
  std::string bytes;
  if (encoding == 0) bytes = "\xEF\xBB\xBF" + text;
  if (encoding == 1 || encoding == 3) bytes = encoding == 1 ? std::string("\xFF\xFE", 2) : "";
  if (encoding == 2 || encoding == 4) bytes = encoding == 2 ? std::string("\xFE\xFF", 2) : "";
  for (char c : text) {
    if (encoding == 1 || encoding == 3) bytes += c, bytes += '\0';
    if (encoding == 2 || encoding == 4) bytes += '\0', bytes += c;
  }
  const auto file =
      bytes_to_file(reinterpret_cast<const uint8_t*>(bytes.data()), bytes.size(), ".csv");
  try {
    (void)organfit::pipeline::read_points_csv(file);
  } catch (const organfit::Error&) {
  }
  return 0;
}
