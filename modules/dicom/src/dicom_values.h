#pragma once
// Parsing DICOM string values, for this module's sources only.
#include <string>
#include <vector>

namespace organfit::dicom::detail {

/// A multi-valued DICOM number string ("1.5\-2\3") as numbers; NaN where a value is not
/// a number (the caller decides whether that is an error).
std::vector<double> numbers(const std::string& value);

}  // namespace organfit::dicom::detail
