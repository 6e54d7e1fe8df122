#pragma once
// A point-set file's data against what its header declares, before VTK reads it.
//
// VTK 9.1's PLY and legacy readers take a file cut short (an interrupted copy) without a
// word: the points its header declares but the file does not hold come out as copies of
// the last one read, or as zeros, and the fit would use them. So a .ply must hold the
// vertices its header declares (ASCII: one line each, with its properties' count of
// values; binary: their bytes), and a legacy .vtk the 3 n values of its POINTS n.
#include <filesystem>

namespace organfit::meshing::detail {

/// Throws InputError "FILE: ..." when a .ply or .vtk file holds less than its header
/// declares, or its header is not one; other files (.vtp: XML, which VTK's parser checks
/// whole) are not judged.
void check_point_file_complete(const std::filesystem::path& file);

}  // namespace organfit::meshing::detail
