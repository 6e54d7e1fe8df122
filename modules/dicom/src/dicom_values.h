#pragma once
// Parsing DICOM string values, for this module's sources only.
#include <string>
#include <vector>

#include "organfit/dicom/part10.h"

namespace organfit::dicom::detail {

/// The SOP Classes of CT slices: CT Image Storage, and the multi-frame Enhanced and Legacy
/// Converted Enhanced CT Image Storage.
inline constexpr const char* kCtImageStorage = "1.2.840.10008.5.1.4.1.1.2";
inline constexpr const char* kEnhancedCtImageStorage = "1.2.840.10008.5.1.4.1.1.2.1";
inline constexpr const char* kLegacyEnhancedCtImageStorage = "1.2.840.10008.5.1.4.1.1.2.2";

/// GDCM's own warnings and errors off: organfit reports every problem itself, in one line.
void quiet_gdcm();

/// False when `file` cannot be handed to GDCM safely: an element that is not well formed
/// in the encoding GDCM will read it in (its File Meta group's transfer syntax; for a raw
/// data set, the encoding GDCM guesses from the first element), a declared length past the
/// end of the file, or bytes after the last element. GDCM 3.0 allocates by declared
/// length before reading, and aborts on assertions on some of these (found by fuzzing).
bool safe_for_gdcm(const std::string& file);

using dicom::is_part10;  // organfit/dicom/part10.h

/// True when a file claims to be DICOM: the Part 10 marker, or a .dcm / .dicom name. Such
/// a file that cannot be read is an error, never "not DICOM".
bool looks_like_dicom(const std::string& file);

/// False when a file's native (unencapsulated) Pixel Data element runs past the end of
/// the file: the element is found by its tag (7FE0,0010) in explicit or implicit little
/// endian, and its declared length must fit.
bool native_pixel_data_complete(const std::string& file);

/// A text value of a data set whose Specific Character Set (0008,0005) is `charset`, as
/// UTF-8 (PS3.3 C.12.1.1.2's defined terms; none declared: ISO-IR 6, bytes above 0x7F
/// read as Latin-1, as pydicom does). False for a character set with code extensions
/// (ISO 2022 ...), whose text is kept as it is, or bytes the character set has not.
bool to_utf8(const std::string& value, const std::string& charset, std::string& utf8);

/// A multi-valued DICOM number string ("1.5\-2\3") as numbers; NaN where a value is not
/// a number (the caller decides whether that is an error).
std::vector<double> numbers(const std::string& value);

}  // namespace organfit::dicom::detail
