#pragma once
// Parsing DICOM string values, for this module's sources only.
#include <string>
#include <vector>

namespace organfit::dicom::detail {

/// GDCM's own warnings and errors off: organfit reports every problem itself, in one line.
void quiet_gdcm();

/// False when `file` cannot be handed to GDCM safely: shorter than its DICOM preamble
/// says, or with a File Meta group (0002) that runs past the end of the file (GDCM 3.0
/// aborts on an assertion there instead of failing).
bool safe_for_gdcm(const std::string& file);

/// True when the file has the DICOM Part 10 marker ("DICM" after a 128-byte preamble).
bool is_part10(const std::string& file);

/// False when a file's native (unencapsulated) Pixel Data element runs past the end of
/// the file: the element is found by its tag (7FE0,0010) in explicit or implicit little
/// endian, and its declared length must fit.
bool native_pixel_data_complete(const std::string& file);

/// A multi-valued DICOM number string ("1.5\-2\3") as numbers; NaN where a value is not
/// a number (the caller decides whether that is an error).
std::vector<double> numbers(const std::string& value);

}  // namespace organfit::dicom::detail
