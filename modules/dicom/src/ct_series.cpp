#include "organfit/dicom/ct_series.h"

#include <fmt/format.h>
#include <gdcmDirectory.h>
#include <gdcmImage.h>
#include <gdcmImageReader.h>
#include <gdcmReader.h>
#include <gdcmScanner.h>
#include <gdcmStringFilter.h>

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <map>
#include <sstream>

#include "dicom_values.h"
#include "organfit/support/error.h"
#include "organfit/support/interrupt.h"

namespace fs = std::filesystem;

namespace organfit::dicom {
namespace {

const gdcm::Tag kModality(0x0008, 0x0060), kSeriesUid(0x0020, 0x000e),
    kSeriesDescription(0x0008, 0x103e), kSopUid(0x0008, 0x0018), kSopClass(0x0008, 0x0016),
    kPosition(0x0020, 0x0032), kOrientation(0x0020, 0x0037), kPixelSpacing(0x0028, 0x0030),
    kRows(0x0028, 0x0010), kColumns(0x0028, 0x0011), kFrameOfReference(0x0020, 0x0052),
    kGantryTilt(0x0018, 0x1120);

std::string trimmed(const char* v) {
  if (!v) return {};
  std::string s(v);
  const auto b = s.find_first_not_of(" \0", 0, 2);
  const auto e = s.find_last_not_of(" \0", std::string::npos, 2);
  return b == std::string::npos ? std::string() : s.substr(b, e - b + 1);
}

using detail::numbers;

struct Header {
  std::string file, series_uid, description, sop_uid, sop_class, frame_of_reference;
  std::vector<double> position, orientation, spacing;
  int rows = 0, columns = 0;
  double tilt = 0;
};

}  // namespace

CtSeries read_ct_series(const fs::path& folder, const CtReadOptions& options) {
  const std::string where = folder.string();
  auto fail = [&](const std::string& why) { throw InputError(where + ": " + why); };
  std::error_code ec;
  if (!fs::is_directory(folder, ec)) fail("not a folder");

  detail::quiet_gdcm();
  gdcm::Directory directory;
  directory.Load(folder.string(), false);
  std::vector<std::string> files;
  int unsafe = 0;  // files that are not DICOM at all: ignored with a warning
  for (const auto& f : directory.GetFilenames()) {
    if (detail::safe_for_gdcm(f)) {
      files.push_back(f);
    } else if (detail::is_part10(f)) {  // a DICOM file whose lengths run past its end
      fail(fs::path(f).filename().string() +
           ": a truncated or corrupt DICOM file (its elements run past its end)");
    } else {
      ++unsafe;
    }
  }
  if (files.empty() && unsafe == 0) fail("the folder is empty: no CT series");
  gdcm::Scanner scanner;
  for (const auto& t :
       {kModality, kSeriesUid, kSeriesDescription, kSopUid, kSopClass, kPosition, kOrientation,
        kPixelSpacing, kRows, kColumns, kFrameOfReference, kGantryTilt})
    scanner.AddTag(t);
  bool scanned = true;
  {
    ReadingInput guard(where.c_str(), "GDCM");
    scanned = files.empty() || scanner.Scan(files);
  }
  if (!scanned) fail("cannot scan the folder");

  CtSeries series;
  int not_dicom = unsafe, other_modality = 0;
  std::map<std::string, std::vector<Header>> by_series;
  for (const auto& f : files) {
    if (!scanner.IsKey(f.c_str())) {
      ++not_dicom;
      continue;
    }
    const std::string modality = trimmed(scanner.GetValue(f.c_str(), kModality));
    if (modality != "CT") {
      ++other_modality;
      continue;
    }
    Header h;
    h.file = f;
    h.series_uid = trimmed(scanner.GetValue(f.c_str(), kSeriesUid));
    h.description = trimmed(scanner.GetValue(f.c_str(), kSeriesDescription));
    h.sop_uid = trimmed(scanner.GetValue(f.c_str(), kSopUid));
    h.sop_class = trimmed(scanner.GetValue(f.c_str(), kSopClass));
    h.frame_of_reference = trimmed(scanner.GetValue(f.c_str(), kFrameOfReference));
    h.position = numbers(trimmed(scanner.GetValue(f.c_str(), kPosition)));
    h.orientation = numbers(trimmed(scanner.GetValue(f.c_str(), kOrientation)));
    h.spacing = numbers(trimmed(scanner.GetValue(f.c_str(), kPixelSpacing)));
    h.rows = std::atoi(trimmed(scanner.GetValue(f.c_str(), kRows)).c_str());
    h.columns = std::atoi(trimmed(scanner.GetValue(f.c_str(), kColumns)).c_str());
    const std::string tilt = trimmed(scanner.GetValue(f.c_str(), kGantryTilt));
    h.tilt = tilt.empty() ? 0.0 : std::atof(tilt.c_str());
    by_series[h.series_uid].push_back(std::move(h));
  }
  if (not_dicom > 0)
    series.warnings.push_back(
        fmt::format("{}: {} file(s) that are not DICOM were ignored", where, not_dicom));
  if (other_modality > 0)
    series.warnings.push_back(
        fmt::format("{}: {} DICOM object(s) that are not CT were ignored", where, other_modality));
  if (by_series.empty()) fail("no CT series (no DICOM file with Modality CT)");

  // Choose the series.
  auto describe = [&]() {
    std::string list;
    for (const auto& [uid, hs] : by_series)
      list += fmt::format("{}{} ('{}', {} slices)", list.empty() ? "" : "; ", uid,
                          hs.front().description, hs.size());
    return list;
  };
  const std::vector<Header>* chosen = nullptr;
  if (!options.series_instance_uid.empty()) {
    auto it = by_series.find(options.series_instance_uid);
    if (it == by_series.end())
      fail("no CT series with UID " + options.series_instance_uid + "; found: " + describe());
    chosen = &it->second;
  } else if (!options.series_description.empty()) {
    for (const auto& [uid, hs] : by_series)
      if (hs.front().description == options.series_description) {
        if (chosen)
          fail("several CT series are described '" + options.series_description +
               "': " + describe());
        chosen = &hs;
      }
    if (!chosen)
      fail("no CT series described '" + options.series_description + "'; found: " + describe());
  } else if (by_series.size() == 1) {
    chosen = &by_series.begin()->second;
  } else {
    fail(fmt::format("{} CT series; choose one by Series Instance UID or description: {}",
                     by_series.size(), describe()));
  }
  std::vector<Header> slices = *chosen;

  // Consistent geometry across slices.
  const Header& first = slices.front();
  if (first.orientation.size() != 6 || first.spacing.size() != 2 || first.position.size() != 3 ||
      first.rows <= 0 || first.columns <= 0)
    fail("slice " + fs::path(first.file).filename().string() +
         " lacks its geometry (orientation, spacing, position or size)");
  for (const auto& h : slices) {
    if (h.rows != first.rows || h.columns != first.columns)
      fail("slices differ in size (" + fs::path(h.file).filename().string() + ")");
    if (h.spacing.size() != 2 || std::abs(h.spacing[0] - first.spacing[0]) > 1e-4 ||
        std::abs(h.spacing[1] - first.spacing[1]) > 1e-4)
      fail("inconsistent pixel spacing (" + fs::path(h.file).filename().string() + ")");
    if (h.orientation.size() != 6 || h.position.size() != 3)
      fail("slice " + fs::path(h.file).filename().string() + " lacks its orientation or position");
    for (int c = 0; c < 6; ++c)
      if (std::abs(h.orientation[c] - first.orientation[c]) > 1e-4)
        fail("slices differ in orientation (" + fs::path(h.file).filename().string() + ")");
    if (std::abs(h.tilt) > 1e-3)
      fail(fmt::format("gantry tilt of {} degrees: tilted series are not supported", h.tilt));
  }
  const Eigen::Vector3d row_dir(first.orientation[0], first.orientation[1], first.orientation[2]);
  const Eigen::Vector3d col_dir(first.orientation[3], first.orientation[4], first.orientation[5]);
  const Eigen::Vector3d normal = row_dir.cross(col_dir).normalized();
  if (std::abs(normal.z()) < 0.99)
    fail(fmt::format("non-axial slices (normal {:.2f}, {:.2f}, {:.2f}): only axial CT is supported",
                     normal.x(), normal.y(), normal.z()));

  // Sort along the normal; detect duplicates, missing slices, irregular gaps and tilt.
  auto along = [&](const Header& h) {
    return normal.dot(Eigen::Vector3d(h.position[0], h.position[1], h.position[2]));
  };
  std::stable_sort(slices.begin(), slices.end(),
                   [&](const Header& a, const Header& b) { return along(a) < along(b); });
  std::vector<double> gaps;
  for (size_t s = 1; s < slices.size(); ++s) {
    const double gap = along(slices[s]) - along(slices[s - 1]);
    if (gap < 1e-3)
      fail(fmt::format("duplicate slice position {:.2f} mm ({} and {})", along(slices[s]),
                       fs::path(slices[s - 1].file).filename().string(),
                       fs::path(slices[s].file).filename().string()));
    gaps.push_back(gap);
  }
  double slice_gap = 1.0;
  if (!gaps.empty()) {
    std::vector<double> sorted = gaps;
    std::nth_element(sorted.begin(), sorted.begin() + sorted.size() / 2, sorted.end());
    slice_gap = sorted[sorted.size() / 2];
    for (size_t s = 0; s < gaps.size(); ++s) {
      if (std::abs(gaps[s] - slice_gap) <= options.spacing_tolerance * slice_gap) continue;
      const double lo = along(slices[s]), hi = along(slices[s + 1]);
      const double ratio = gaps[s] / slice_gap;
      if (std::abs(ratio - std::round(ratio)) < 0.05 && ratio > 1.5)
        fail(
            fmt::format("missing slice: a gap of {:.2f} mm between {:.2f} and {:.2f} mm (slices "
                        "are {:.2f} mm apart)",
                        gaps[s], lo, hi, slice_gap));
      fail(fmt::format(
          "irregular slice spacing: {:.2f} mm between {:.2f} and {:.2f} mm, {:.2f} mm elsewhere",
          gaps[s], lo, hi, slice_gap));
    }
    // Positions must advance along the normal only (else the series is tilted or sheared).
    const Eigen::Vector3d p0(first.position[0], first.position[1], first.position[2]);
    for (const auto& h : slices) {
      const Eigen::Vector3d d = Eigen::Vector3d(h.position[0], h.position[1], h.position[2]) - p0;
      if ((d - normal.dot(d) * normal).norm() > 0.01 * slice_gap + 1e-3)
        fail(
            "slice positions do not advance along the slice normal (gantry tilt or a sheared "
            "series)");
    }
  }

  // Geometry.
  geometry::ImageGeometry& g = series.geometry;
  g.size = {first.columns, first.rows, static_cast<int>(slices.size())};
  g.spacing_mm = Eigen::Vector3d(first.spacing[1], first.spacing[0], slice_gap);
  g.origin_mm = Eigen::Vector3d(slices.front().position[0], slices.front().position[1],
                                slices.front().position[2]);
  g.direction.col(0) = row_dir;
  g.direction.col(1) = col_dir;
  g.direction.col(2) = normal;
  series.series_instance_uid = first.series_uid;
  series.series_description = first.description;
  series.frame_of_reference_uid = first.frame_of_reference;

  // Pixels, in HU.
  const size_t per_slice = static_cast<size_t>(first.rows) * first.columns;
  series.hu.resize(per_slice * slices.size());
  for (size_t s = 0; s < slices.size(); ++s) {
    throw_if_interrupted();
    const std::string name = fs::path(slices[s].file).filename().string();
    gdcm::ImageReader reader;
    reader.SetFileName(slices[s].file.c_str());
    bool read_ok = false;
    {
      ReadingInput guard(slices[s].file.c_str(), "GDCM");
      read_ok = reader.Read();
    }
    if (!read_ok) fail("cannot read the pixels of " + name + " (truncated or unsupported)");
    const gdcm::Image& image = reader.GetImage();
    const gdcm::PixelFormat pf = image.GetPixelFormat();
    if (pf.GetSamplesPerPixel() != 1) fail(name + ": not a grey-scale image");
    std::vector<char> buffer(image.GetBufferLength());
    if (!image.GetBuffer(buffer.data())) fail("cannot decode the pixels of " + name);
    if (buffer.size() < per_slice * pf.GetPixelSize())
      fail(name + ": pixel data shorter than its size says");
    // GDCM reads a file cut short inside its pixel data with only a warning: refuse it.
    if (!reader.GetFile().GetHeader().GetDataSetTransferSyntax().IsEncapsulated() &&
        !detail::native_pixel_data_complete(slices[s].file))
      fail(name + ": its pixel data is cut short (a truncated file)");
    const double slope = image.GetSlope(), intercept = image.GetIntercept();
    float* out = series.hu.data() + s * per_slice;
    for (size_t v = 0; v < per_slice; ++v) {
      double raw = 0;
      switch (pf.GetScalarType()) {
        case gdcm::PixelFormat::INT16:
          raw = reinterpret_cast<const int16_t*>(buffer.data())[v];
          break;
        case gdcm::PixelFormat::UINT16:
          raw = reinterpret_cast<const uint16_t*>(buffer.data())[v];
          break;
        case gdcm::PixelFormat::INT8:
          raw = reinterpret_cast<const int8_t*>(buffer.data())[v];
          break;
        case gdcm::PixelFormat::UINT8:
          raw = reinterpret_cast<const uint8_t*>(buffer.data())[v];
          break;
        case gdcm::PixelFormat::INT32:
          raw = reinterpret_cast<const int32_t*>(buffer.data())[v];
          break;
        case gdcm::PixelFormat::UINT32:
          raw = reinterpret_cast<const uint32_t*>(buffer.data())[v];
          break;
        default:
          fail(name + ": unsupported pixel type");
      }
      out[v] = static_cast<float>(raw * slope + intercept);
    }
    series.slices.push_back(
        {slices[s].sop_uid, slices[s].sop_class,
         Eigen::Vector3d(slices[s].position[0], slices[s].position[1], slices[s].position[2]),
         slices[s].file});
    if (s == 0) {  // patient and study, copied later into exported objects
      gdcm::StringFilter sf;
      sf.SetFile(reader.GetFile());
      auto get = [&](uint16_t gr, uint16_t el) {
        return trimmed(sf.ToString(gdcm::Tag(gr, el)).c_str());
      };
      PatientStudy& p = series.patient;
      p.patient_name = get(0x0010, 0x0010);
      p.patient_id = get(0x0010, 0x0020);
      p.patient_birth_date = get(0x0010, 0x0030);
      p.patient_sex = get(0x0010, 0x0040);
      p.study_instance_uid = get(0x0020, 0x000d);
      p.study_id = get(0x0020, 0x0010);
      p.study_date = get(0x0008, 0x0020);
      p.study_time = get(0x0008, 0x0030);
      p.study_description = get(0x0008, 0x1030);
      p.accession_number = get(0x0008, 0x0050);
      p.referring_physician_name = get(0x0008, 0x0090);
    }
  }
  return series;
}

}  // namespace organfit::dicom
