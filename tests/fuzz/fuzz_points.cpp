// The point-set CSV reader on arbitrary bytes.
#include "fuzz_util.h"
#include "organfit/pipeline/points_file.h"
#include "organfit/support/error.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const auto file = bytes_to_file(data, size, ".csv");
  try {
    (void)organfit::pipeline::read_points_csv(file);
  } catch (const organfit::Error&) {
  }
  return 0;
}
