#pragma once
// Attractive points read from a text table, as spreadsheets and scripts write them.
//
// Encodings: UTF-8 (with or without its byte-order mark), UTF-16 LE or BE (with its mark,
// as Excel's "Unicode text" writes it); line ends LF, CRLF or CR. Columns x, y, z in mm
// (patient coordinates) and an optional confidence in (0, 1], separated by commas,
// semicolons (then a decimal comma is allowed: "1,5;2;3"), tabs or spaces; cells may
// be quoted. '#' starts a comment line; one header line of text may come first. A header
// that names its columns x, y and z other than first, second and third ("id,x,y,z",
// "label;Z (mm);X (mm);Y (mm)") has those columns read, and one named "confidence"; else the
// first three are x, y, z and a fourth the confidence. The numbers are read as mm LPS, so
// a header saying otherwise of its coordinate columns is refused: named in another unit
// ("x_cm", "Y (m)", "z inches"), named R, A, S (or RAS), i, j, k (voxel indices), or L, P,
// S in another order ("S,P,L").
//
// 3D Slicer's markups table (.fcsv) is read by what its comment lines declare: "# columns =
// id,x,y,z,..." (its x, y and z columns taken, the id and label beside them left) and
// "# CoordinateSystem = LPS" or RAS (Slicer 4 wrote 1 or 0): RAS is turned into LPS (x and y
// negated), since the file says which it is.
//
// The CT the points are in may be declared in comment lines, as `organfit us-points --ct`
// writes them: "# series_instance_uid: UID" and "# frame_of_reference_uid: UID". A run
// refuses points declared in another CT than its planning CT.
#include <filesystem>
#include <string>
#include <vector>

#include "organfit/fitting/attractive_points.h"

namespace organfit::pipeline {

/// Most points a file may hold: beyond it a file is refused before any work (a fit's cost
/// grows with the count; 100,000 points fit within the default wall budget).
constexpr long kMaxPointsInFile = 100000;
/// No coordinate of a patient lies this far from the scanner's origin (10 m, in mm): a
/// larger one is a unit or column mistake.
constexpr double kMaxCoordinateMm = 10000.0;

/// The CT a point table declares it is in (empty strings: not declared).
struct PointsCt {
  std::string series_instance_uid, frame_of_reference_uid;
};

/// A point table as read: its points and the CT it declares.
struct PointsTable {
  std::vector<fitting::AttractivePoint> points;
  PointsCt ct;
};

/// Reads a point table. Throws InputError "FILE:LINE: reason" on text where a number
/// belongs, a wrong number of columns, NaN or Inf, a coordinate beyond kMaxCoordinateMm, a
/// confidence outside (0, 1]; "FILE: reason" on an unreadable or undecodable file, no
/// points, or more than kMaxPointsInFile.
PointsTable read_points_table(const std::filesystem::path& file);
/// Its points alone.
std::vector<fitting::AttractivePoint> read_points_csv(const std::filesystem::path& file);

/// The comment lines that declare `ct` (empty when nothing is declared).
std::string points_ct_comment(const PointsCt& ct);

}  // namespace organfit::pipeline
