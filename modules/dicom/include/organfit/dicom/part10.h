#pragma once
// Whether a file is a DICOM Part 10 file, by its marker alone (no parsing).
#include <filesystem>

namespace organfit::dicom {

/// True when the file has the DICOM Part 10 marker ("DICM" after a 128-byte preamble).
bool is_part10(const std::filesystem::path& file);

}  // namespace organfit::dicom
