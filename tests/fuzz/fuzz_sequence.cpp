// The PLUS sequence metafile reader and the sweep assembly on arbitrary bytes.
#include "fuzz_util.h"
#include "organfit/support/error.h"
#include "organfit/ultrasound/sequence_metafile.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const auto file = bytes_to_file(data, size, ".mha");
  try {
    const auto s = organfit::ultrasound::read_sequence_metafile(file);
    (void)organfit::ultrasound::assemble_sweep(s, nullptr, {});
  } catch (const organfit::Error&) {
  }
  return 0;
}
