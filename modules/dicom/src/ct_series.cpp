#include "organfit/dicom/ct_series.h"

#include <fmt/format.h>
#include <gdcmDict.h>
#include <gdcmDicts.h>
#include <gdcmGlobal.h>
#include <gdcmImage.h>
#include <gdcmImageReader.h>
#include <gdcmReader.h>
#include <gdcmScanner.h>
#include <gdcmSequenceOfItems.h>
#include <gdcmStringFilter.h>

#include <Eigen/Geometry>
#include <algorithm>
#include <array>
#include <cmath>
#include <map>
#include <set>
#include <sstream>
#include <tuple>

#include "dicom_values.h"
#include "dicom_writing.h"
#include "organfit/support/error.h"
#include "organfit/support/interrupt.h"
#include "organfit/support/progress.h"

namespace fs = std::filesystem;

namespace organfit::dicom {
namespace {

const gdcm::Tag kModality(0x0008, 0x0060), kSeriesUid(0x0020, 0x000e),
    kSeriesDescription(0x0008, 0x103e), kSopUid(0x0008, 0x0018), kSopClass(0x0008, 0x0016),
    kPosition(0x0020, 0x0032), kOrientation(0x0020, 0x0037), kPixelSpacing(0x0028, 0x0030),
    kRows(0x0028, 0x0010), kColumns(0x0028, 0x0011), kFrameOfReference(0x0020, 0x0052),
    kGantryTilt(0x0018, 0x1120), kSliceThickness(0x0018, 0x0050),
    kSpacingBetweenSlices(0x0018, 0x0088), kStudyUid(0x0020, 0x000d),
    kRescaleIntercept(0x0028, 0x1052), kRescaleSlope(0x0028, 0x1053),
    kSamplesPerPixel(0x0028, 0x0002), kPhotometric(0x0028, 0x0004), kBitsAllocated(0x0028, 0x0100),
    kBitsStored(0x0028, 0x0101), kHighBit(0x0028, 0x0102), kPixelRepresentation(0x0028, 0x0103),
    kNumberOfFrames(0x0028, 0x0008), kImageType(0x0008, 0x0008);

std::string trimmed(const char* v) {
  if (!v) return {};
  std::string s(v);
  const auto b = s.find_first_not_of(" \0", 0, 2);
  const auto e = s.find_last_not_of(" \0", std::string::npos, 2);
  return b == std::string::npos ? std::string() : s.substr(b, e - b + 1);
}

using detail::kCtImageStorage, detail::kEnhancedCtImageStorage,
    detail::kLegacyEnhancedCtImageStorage;
using detail::numbers;

/// Whether an Image Type (0008,0008, as "ORIGINAL\PRIMARY\LOCALIZER") names a localizer:
/// its third value.
bool is_localizer(const std::string& image_type) {
  std::string third;
  for (size_t at = 0, value = 0; at <= image_type.size(); ++value) {
    const size_t end = std::min(image_type.find('\\', at), image_type.size());
    if (value == 2) third = trimmed(image_type.substr(at, end - at).c_str());
    at = end + 1;
  }
  return third == "LOCALIZER";
}

struct Header {
  std::string file, series_uid, description, sop_uid, sop_class, frame_of_reference, study_uid;
  std::string intercept, slope;  ///< as stated (empty: not stated)
  /// Samples per pixel, photometric interpretation, bits allocated, stored, high bit and
  /// pixel representation, as stated: how its stored values are laid out.
  std::array<std::string, 6> pixel_layout;
  std::vector<double> position, orientation, spacing;
  int rows = 0, columns = 0, frames = 1;
  double tilt = 0, thickness = 0, spacing_between = 0;  ///< mm; 0 when not stated
};

}  // namespace

CtSeries read_ct_series(const fs::path& folder, const CtReadOptions& options) {
  const std::string where = folder.string();
  auto fail = [&](const std::string& why) { throw InputError(where + ": " + why); };
  std::error_code ec;
  if (!fs::is_directory(folder, ec)) fail("not a folder");

  detail::quiet_gdcm();
  // The folder is listed here, entry by entry, so that no entry stops the listing and
  // none is lost without a word: what is not a regular file is counted and skipped.
  std::vector<std::string> files;
  int unsafe = 0;     // files that are not DICOM at all: ignored with a warning
  int irregular = 0;  // FIFOs, sockets, devices, folders, dangling or looping links
  {
    fs::directory_iterator it(folder, ec), end;
    if (ec) fail("cannot list the folder: " + ec.message());
    for (; it != end; it.increment(ec)) {
      if (ec) fail("cannot list the folder: " + ec.message());
      std::error_code status_ec;
      if (!fs::is_regular_file(it->path(), status_ec)) {  // follows links to files
        ++irregular;
        continue;
      }
      const std::string f = it->path().string();
      if (detail::safe_for_gdcm(f)) {
        files.push_back(f);
      } else if (detail::looks_like_dicom(f)) {  // a DICOM file whose lengths run past its end
        fail(it->path().filename().string() +
             ": a truncated or corrupt DICOM file (its elements run past its end, or it cannot "
             "be read)");
      } else {
        ++unsafe;
      }
    }
    if (ec) fail("cannot list the folder: " + ec.message());
  }
  std::sort(files.begin(), files.end());
  if (files.empty() && unsafe == 0 && irregular == 0) fail("the folder is empty: no CT series");
  const gdcm::Tag header_tags[] = {kModality,
                                   kSeriesUid,
                                   kSeriesDescription,
                                   kSopUid,
                                   kSopClass,
                                   kPosition,
                                   kOrientation,
                                   kPixelSpacing,
                                   kRows,
                                   kColumns,
                                   kFrameOfReference,
                                   kGantryTilt,
                                   kSliceThickness,
                                   kSpacingBetweenSlices,
                                   kStudyUid,
                                   kRescaleIntercept,
                                   kRescaleSlope,
                                   kSamplesPerPixel,
                                   kPhotometric,
                                   kBitsAllocated,
                                   kBitsStored,
                                   kHighBit,
                                   kPixelRepresentation,
                                   kNumberOfFrames,
                                   kImageType};
  gdcm::Scanner scanner;
  for (const auto& t : header_tags)
    scanner.AddTag(t);
  bool scanned = true;
  {
    ReadingInput guard(where.c_str(), "GDCM");
    scanned = files.empty() || scanner.Scan(files);
  }
  if (!scanned) fail("cannot scan the folder");

  CtSeries series;
  int not_dicom = unsafe, other_modality = 0;
  // Localizers (scout, topogram: Image Type's third value LOCALIZER) are projections that
  // a CT study's export holds beside its volume, never a slice of one: left out, counted.
  std::map<std::string, std::pair<std::string, int>> localizers;  // series: description, images
  std::map<std::string, std::pair<std::string, int>> not_images;  // the same, other SOP classes
  std::map<std::string, std::vector<Header>> by_series;
  for (const auto& f : files) {
    // The scanner reads headers only up to the tags it needs and cannot do so in every
    // transfer syntax (a deflated data set): such a file's header is read whole instead.
    std::map<gdcm::Tag, std::string> read_whole;
    if (!scanner.IsKey(f.c_str())) {
      gdcm::Reader reader;
      reader.SetFileName(f.c_str());
      bool read_ok = false;
      {
        ReadingInput guard(f.c_str(), "GDCM");
        read_ok = reader.Read();
      }
      if (!read_ok) {
        if (detail::looks_like_dicom(f))
          fail(fs::path(f).filename().string() + ": a DICOM file that cannot be read");
        ++not_dicom;
        continue;
      }
      gdcm::StringFilter sf;
      sf.SetFile(reader.GetFile());
      for (const auto& t : header_tags)
        if (reader.GetFile().GetDataSet().FindDataElement(t)) read_whole[t] = sf.ToString(t);
    }
    auto value = [&](const gdcm::Tag& t) -> std::string {
      if (scanner.IsKey(f.c_str())) return trimmed(scanner.GetValue(f.c_str(), t));
      const auto it = read_whole.find(t);
      return it == read_whole.end() ? std::string() : trimmed(it->second.c_str());
    };
    const std::string modality = value(kModality);
    if (modality != "CT") {
      ++other_modality;
      continue;
    }
    // Only CT Image Storage objects are slices (the Enhanced ones are named below): a
    // scanner's screen captures (a dose report, a protocol page: Secondary Capture) and
    // private objects carry Modality CT too, in series of their own.
    if (const std::string sop_class = value(kSopClass);
        !sop_class.empty() && sop_class != kCtImageStorage &&
        sop_class != kEnhancedCtImageStorage && sop_class != kLegacyEnhancedCtImageStorage) {
      auto& [description, objects] = not_images[value(kSeriesUid)];
      description = value(kSeriesDescription);
      ++objects;
      continue;
    }
    if (is_localizer(value(kImageType))) {
      auto& [description, images] = localizers[value(kSeriesUid)];
      description = value(kSeriesDescription);
      ++images;
      continue;
    }
    Header h;
    h.file = f;
    h.series_uid = value(kSeriesUid);
    h.description = value(kSeriesDescription);
    h.sop_uid = value(kSopUid);
    h.sop_class = value(kSopClass);
    h.frame_of_reference = value(kFrameOfReference);
    h.study_uid = value(kStudyUid);
    h.intercept = value(kRescaleIntercept);
    h.slope = value(kRescaleSlope);
    h.pixel_layout = {value(kSamplesPerPixel), value(kPhotometric), value(kBitsAllocated),
                      value(kBitsStored),      value(kHighBit),     value(kPixelRepresentation)};
    h.position = numbers(value(kPosition));
    h.orientation = numbers(value(kOrientation));
    h.spacing = numbers(value(kPixelSpacing));
    h.rows = std::atoi(value(kRows).c_str());
    h.columns = std::atoi(value(kColumns).c_str());
    if (const std::string frames = value(kNumberOfFrames); !frames.empty())
      h.frames = std::atoi(frames.c_str());
    const std::string tilt = value(kGantryTilt);
    h.tilt = tilt.empty() ? 0.0 : std::atof(tilt.c_str());
    auto positive = [&](const gdcm::Tag& t) {
      const double v = std::atof(value(t).c_str());
      return std::isfinite(v) && v > 0 ? v : 0.0;
    };
    h.thickness = positive(kSliceThickness);
    h.spacing_between = positive(kSpacingBetweenSlices);
    by_series[h.series_uid].push_back(std::move(h));
  }
  if (irregular > 0)
    series.warnings.push_back(fmt::format(
        "{}: {} entr{} that are not regular files (folders, FIFOs, sockets, devices, dangling or "
        "looping links) were skipped",
        where, irregular, irregular == 1 ? "y" : "ies"));
  if (not_dicom > 0)
    series.warnings.push_back(
        fmt::format("{}: {} file(s) that are not DICOM were ignored", where, not_dicom));
  if (other_modality > 0)
    series.warnings.push_back(
        fmt::format("{}: {} DICOM object(s) that are not CT were ignored", where, other_modality));
  // Objects left out, in one warning: how many, and their series' descriptions.
  auto warn_left_out = [&](const std::map<std::string, std::pair<std::string, int>>& seen,
                           const char* what) {
    if (seen.empty()) return;
    int objects = 0;
    std::string named;
    for (const auto& [uid, series_seen] : seen) {
      objects += series_seen.second;
      named += fmt::format("{}'{}'", named.empty() ? "" : ", ", echo(series_seen.first, 40));
    }
    series.warnings.push_back(
        fmt::format("{}: {} {} were ignored: series {}", where, objects, what, echo(named, 200)));
  };
  warn_left_out(localizers, "localizer image(s) (scout or topogram: Image Type LOCALIZER)");
  warn_left_out(not_images,
                "object(s) of Modality CT that are not CT images (another SOP Class: a screen "
                "capture, a dose report)");
  if (by_series.empty())
    fail(localizers.empty() && not_images.empty()
             ? "no CT series (no DICOM file with Modality CT)"
             : "no CT series: only localizers (scout or topogram images) or other objects of "
               "Modality CT");
  // One SOP Instance UID, one image: two files claiming the same one are two exports of a
  // slice, or a copy edited by hand; which is the CT cannot be told.
  {
    std::map<std::string, std::string> file_of_uid;
    for (const auto& [uid, hs] : by_series)
      for (const auto& h : hs) {
        if (h.sop_uid.empty()) continue;
        const auto [it, fresh] = file_of_uid.emplace(h.sop_uid, h.file);
        if (!fresh)
          fail(fmt::format("{} and {} have the same SOP Instance UID",
                           fs::path(it->second).filename().string(),
                           fs::path(h.file).filename().string()));
      }
  }

  // Choose the series.
  auto describe = [&]() {
    std::string list;
    for (const auto& [uid, hs] : by_series)
      list += fmt::format("{}{} ('{}', {} slices)", list.empty() ? "" : "; ", echo(uid, 64),
                          echo(hs.front().description, 40), hs.size());
    return echo(list, 400);
  };
  const std::vector<Header>* chosen = nullptr;
  if (!options.series_instance_uid.empty()) {
    auto it = by_series.find(options.series_instance_uid);
    if (it == by_series.end())
      fail("no CT series with UID " + echo(options.series_instance_uid) + "; found: " + describe());
    chosen = &it->second;
  } else if (!options.series_description.empty()) {
    for (const auto& [uid, hs] : by_series)
      if (hs.front().description == options.series_description) {
        if (chosen)
          fail("several CT series are described '" + echo(options.series_description) +
               "': " + describe());
        chosen = &hs;
      }
    if (!chosen)
      fail("no CT series described '" + echo(options.series_description) +
           "'; found: " + describe());
  } else if (by_series.size() == 1) {
    chosen = &by_series.begin()->second;
  } else {
    // The series the inputs reference (a structure set, a planning model), when it is here
    // and alone.
    std::set<std::string> referenced;
    for (const auto& uid : options.referenced_series_uids)
      if (by_series.count(uid)) referenced.insert(uid);
    if (referenced.size() != 1)
      fail(fmt::format("{} CT series; choose one by Series Instance UID or description{}: {}",
                       by_series.size(),
                       options.referenced_series_uids.empty()
                           ? ""
                           : fmt::format(" ({} references {})", options.referenced_by,
                                         referenced.empty() ? "none of them" : "several"),
                       describe()));
    chosen = &by_series.at(*referenced.begin());
    series.choice = fmt::format(
        "series '{}' ({} slices) read: the series {} references, of {} CT "
        "series",
        echo(chosen->front().description, 64), chosen->size(), options.referenced_by,
        by_series.size());
  }
  std::vector<Header> slices = *chosen;

  // Consistent geometry across slices, judged against what most slices say, so that an
  // error names the odd slice rather than whichever was read first.
  auto name_of = [](const Header& h) { return fs::path(h.file).filename().string(); };
  for (const auto& h : slices)
    // An Enhanced CT (or a legacy series converted to one) holds the whole scan in one
    // object, its geometry frame by frame in functional groups.
    if (h.frames > 1 || h.sop_class == kEnhancedCtImageStorage ||
        h.sop_class == kLegacyEnhancedCtImageStorage)
      fail(fmt::format(
          "{} is a multi-frame CT object (Enhanced CT, {} frames): organfit reads a series of "
          "single-frame CT images (CT Image Storage); export the scan as those from the "
          "scanner or PACS",
          name_of(h), h.frames));
  for (const auto& h : slices)
    if (h.orientation.size() != 6 || h.spacing.size() != 2 || h.position.size() != 3 ||
        h.rows <= 0 || h.columns <= 0)
      fail("slice " + name_of(h) + " lacks its geometry (orientation, spacing, position or size)");
  auto most_common = [&](auto key) {
    std::map<decltype(key(slices.front())), int> count;
    for (const auto& h : slices)
      ++count[key(h)];
    return std::max_element(count.begin(), count.end(),
                            [](const auto& a, const auto& b) { return a.second < b.second; })
        ->first;
  };
  const auto size = most_common([](const Header& h) { return std::make_pair(h.rows, h.columns); });
  const auto spacing = most_common([](const Header& h) {
    return std::make_pair(std::lround(h.spacing[0] * 1e4), std::lround(h.spacing[1] * 1e4));
  });
  const auto orientation = most_common([](const Header& h) {
    std::array<long, 6> o{};
    for (int c = 0; c < 6; ++c)
      o[c] = std::lround(h.orientation[c] * 1e4);
    return o;
  });
  const Header* reference = nullptr;
  for (const auto& h : slices) {
    if (std::make_pair(h.rows, h.columns) != size)
      fail(fmt::format("slice {} is {} x {} pixels, the others {} x {}: slices differ in size",
                       name_of(h), h.columns, h.rows, size.second, size.first));
    if (std::abs(h.spacing[0] * 1e4 - spacing.first) > 1 ||
        std::abs(h.spacing[1] * 1e4 - spacing.second) > 1)
      fail(fmt::format(
          "slice {} has inconsistent pixel spacing ({:g} x {:g} mm, the others {:g} x "
          "{:g})",
          name_of(h), h.spacing[0], h.spacing[1], spacing.first * 1e-4, spacing.second * 1e-4));
    for (int c = 0; c < 6; ++c)
      if (std::abs(h.orientation[c] * 1e4 - orientation[c]) > 1)
        fail("slices differ in orientation (" + name_of(h) + ")");
    if (std::abs(h.tilt) > 1e-3)
      fail(fmt::format("gantry tilt of {} degrees: tilted series are not supported", h.tilt));
    if (!reference) reference = &h;
  }
  // One scan: every slice of the series in the same study and frame of reference, each with
  // the SOP Instance UID an exported structure set references it by, and its stored values
  // mapped to HU alike (a slice without the Rescale Intercept the others state would be off
  // by it, -1024 HU on most scanners). A slice that differs is of another scan, or edited.
  for (const auto& h : slices)
    if (h.sop_uid.empty())
      fail("slice " + name_of(h) +
           " has no SOP Instance UID (an exported structure set could not reference it)");
  const std::string frame = most_common([](const Header& h) { return h.frame_of_reference; });
  const std::string study = most_common([](const Header& h) { return h.study_uid; });
  const bool intercepts = most_common([](const Header& h) { return !h.intercept.empty(); });
  const bool slopes = most_common([](const Header& h) { return !h.slope.empty(); });
  const auto layout = most_common([](const Header& h) { return h.pixel_layout; });
  for (const auto& h : slices) {
    if (h.frame_of_reference != frame)
      fail("slice " + name_of(h) +
           "'s Frame of Reference UID is not the other slices' (a slice of another scan, or an "
           "edited one)");
    if (h.study_uid != study)
      fail("slice " + name_of(h) +
           "'s Study Instance UID is not the other slices' (a slice of another study, or an "
           "edited one)");
    for (const auto& [stated, most, what] :
         {std::tuple{!h.intercept.empty(), intercepts, "Rescale Intercept"},
          std::tuple{!h.slope.empty(), slopes, "Rescale Slope"}})
      if (stated != most)
        fail("slice " + name_of(h) + (most ? " states no " : " alone states a ") + what +
             " where the other slices " + (most ? "do" : "do not") +
             ": its HU would not be theirs");
    if (h.pixel_layout != layout)
      fail("slice " + name_of(h) +
           "'s pixels are described otherwise than the other slices' (samples per pixel, "
           "photometric interpretation, bits allocated, stored, high bit or pixel "
           "representation)");
  }
  // The layout they share, as DICOM allows it: whole bytes allocated, the stored bits
  // within them and ending at the high bit, unsigned or two's complement.
  {
    auto as_int = [](const std::string& v) { return v.empty() ? -1 : std::atoi(v.c_str()); };
    const int allocated = as_int(layout[2]), stored = as_int(layout[3]), high = as_int(layout[4]),
              representation = as_int(layout[5]);
    if (!(allocated == 8 || allocated == 16 || allocated == 32) || stored < 1 ||
        stored > allocated || high != stored - 1 || (representation != 0 && representation != 1))
      fail(fmt::format(
          "its slices state bits allocated {}, stored {}, high bit {} and pixel representation "
          "{}: not a layout of stored values DICOM allows",
          echo(layout[2], 8), echo(layout[3], 8), echo(layout[4], 8), echo(layout[5], 8)));
  }
  if (!intercepts && !slopes)
    series.warnings.push_back(where +
                              ": no slice states a Rescale Slope or Intercept: the stored values "
                              "are taken as HU");
  const Header first = *reference;  // a copy: the slices are sorted below
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
  double slice_gap = 0;
  if (gaps.empty()) {
    // One slice: its thickness is stated, never assumed.
    slice_gap = first.spacing_between > 0 ? first.spacing_between : first.thickness;
    if (!(slice_gap > 0))
      fail("slice " + name_of(first) +
           " is the only one and states neither Spacing Between Slices nor Slice Thickness: its "
           "thickness is unknown");
  } else {
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
                        "are {:.2f} mm apart; between {} and {})",
                        gaps[s], lo, hi, slice_gap, name_of(slices[s]), name_of(slices[s + 1])));
      // The odd slice: the one farthest from the regular lattice the others lie on.
      std::vector<double> offsets;
      for (size_t k = 0; k < slices.size(); ++k)
        offsets.push_back(along(slices[k]) - slice_gap * static_cast<double>(k));
      std::vector<double> sorted_offsets = offsets;
      std::nth_element(sorted_offsets.begin(), sorted_offsets.begin() + sorted_offsets.size() / 2,
                       sorted_offsets.end());
      const double lattice = sorted_offsets[sorted_offsets.size() / 2];
      size_t odd = 0;
      for (size_t k = 1; k < slices.size(); ++k)
        if (std::abs(offsets[k] - lattice) > std::abs(offsets[odd] - lattice)) odd = k;
      fail(fmt::format(
          "irregular slice spacing: slice {} lies at {:.2f} mm, {:+.2f} mm off the {:.2f} mm "
          "spacing of the others ({:.2f} mm between {:.2f} and {:.2f} mm)",
          name_of(slices[odd]), along(slices[odd]), offsets[odd] - lattice, slice_gap, gaps[s], lo,
          hi));
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
  series.folder = folder;
  series.series_instance_uid = first.series_uid;
  series.series_description = first.description;
  series.frame_of_reference_uid = first.frame_of_reference;

  // Pixels, in HU.
  const size_t per_slice = static_cast<size_t>(first.rows) * first.columns;
  series.hu.resize(per_slice * slices.size());
  Progress progress("ct: reading pixels", static_cast<long long>(slices.size()));
  for (size_t s = 0; s < slices.size(); ++s) {
    throw_if_interrupted();
    progress.update(static_cast<long long>(s));
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
    // Native pixel data hold exactly the image's bytes (one more to make the length even):
    // a shorter element leaves part of the slice unread (GDCM fills it without a word), a
    // longer one is not the image its rows, columns and bits allocated describe.
    if (const gdcm::ByteValue* stored = image.GetDataElement().GetByteValue();
        stored && !reader.GetFile().GetHeader().GetDataSetTransferSyntax().IsEncapsulated()) {
      const size_t expected = per_slice * pf.GetPixelSize();
      const size_t length = stored->GetLength();
      if (length != expected && length != expected + expected % 2)
        fail(fmt::format(
            "{}: its pixel data hold {} bytes where its {} x {} pixels of {} bytes take {}", name,
            length, first.columns, first.rows, pf.GetPixelSize(), expected));
    }
    // GDCM reads a file cut short inside its pixel data with only a warning: refuse it.
    if (!reader.GetFile().GetHeader().GetDataSetTransferSyntax().IsEncapsulated() &&
        !detail::native_pixel_data_complete(slices[s].file))
      fail(name + ": its pixel data is cut short (a truncated file)");
    const double slope = image.GetSlope(), intercept = image.GetIntercept();
    float* out = series.hu.data() + s * per_slice;
    // The stored type chosen once a slice, not once a voxel (105 million on a thin CT).
    auto convert = [&](auto stored) {
      using T = decltype(stored);
      const T* in = reinterpret_cast<const T*>(buffer.data());
      for (size_t v = 0; v < per_slice; ++v)
        out[v] = static_cast<float>(static_cast<double>(in[v]) * slope + intercept);
    };
    switch (pf.GetScalarType()) {
      case gdcm::PixelFormat::INT16:
        convert(int16_t{});
        break;
      case gdcm::PixelFormat::UINT16:
        convert(uint16_t{});
        break;
      case gdcm::PixelFormat::INT8:
        convert(int8_t{});
        break;
      case gdcm::PixelFormat::UINT8:
        convert(uint8_t{});
        break;
      case gdcm::PixelFormat::INT32:
        convert(int32_t{});
        break;
      case gdcm::PixelFormat::UINT32:
        convert(uint32_t{});
        break;
      default:
        fail(name + ": unsupported pixel type");
    }
    // CT numbers run from -1024 HU (air) to a few tens of thousands on an extended scale
    // (metal): a slope or intercept that maps the stored values far beyond is not a CT's.
    constexpr double kLargestHu = 1e5;
    const auto [lo, hi] = std::minmax_element(out, out + per_slice);
    if (per_slice > 0 && !(std::abs(*lo) <= kLargestHu && std::abs(*hi) <= kLargestHu))
      fail(fmt::format(
          "{}: its Rescale Slope {:g} and Intercept {:g} map its stored values to {:g} .. {:g} "
          "HU: not CT numbers",
          name, slope, intercept, *lo, *hi));
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
      PatientStudy as_read;
      as_read.patient_name = get(0x0010, 0x0010);
      as_read.patient_id = get(0x0010, 0x0020);
      as_read.patient_birth_date = get(0x0010, 0x0030);
      as_read.patient_sex = get(0x0010, 0x0040);
      as_read.study_instance_uid = get(0x0020, 0x000d);
      as_read.study_id = get(0x0020, 0x0010);
      as_read.study_date = get(0x0008, 0x0020);
      as_read.study_time = get(0x0008, 0x0030);
      as_read.study_description = get(0x0008, 0x1030);
      as_read.accession_number = get(0x0008, 0x0050);
      as_read.referring_physician_name = get(0x0008, 0x0090);
      // Text in the source's character set becomes UTF-8, which organfit declares; in a
      // set it cannot convert (ISO 2022 code extensions) it is kept, with that set.
      const std::string charset = get(0x0008, 0x0005);
      // The modules' other attributes, whole (sequences included), with their VRs made
      // explicit where an implicit-VR file has none (the dictionary's).
      auto raw = std::make_shared<CopiedModules>();
      const gdcm::Dict& dict = gdcm::Global::GetInstance().GetDicts().GetPublicDict();
      const gdcm::DataSet& source = reader.GetFile().GetDataSet();
      for (auto at = source.Begin(); at != source.End(); ++at) {
        const gdcm::DataElement& de = *at;
        if (!detail::is_copied_patient_or_study_tag(de.GetTag())) continue;
        gdcm::DataElement copy = de;
        if (copy.GetVR() == gdcm::VR::INVALID || copy.GetVR() == gdcm::VR::UN) {
          const gdcm::VR vr = dict.GetDictEntry(de.GetTag()).GetVR();
          if (vr == gdcm::VR::INVALID || vr == gdcm::VR::UN) continue;
          if (vr == gdcm::VR::US_SS || vr == gdcm::VR::OB_OW || vr == gdcm::VR::US_SS_OW)
            continue;  // a VR only the data could tell: left out
          if (vr == gdcm::VR::SQ && !de.GetValueAsSQ()) continue;  // not parsed: left out
          copy.SetVR(vr);
        }
        raw->elements.Insert(copy);
      }
      PatientStudy& p = series.patient;
      p = as_read;
      auto converted = std::make_shared<CopiedModules>(*raw);
      bool all_converted = true;
      for (std::string* text : {&p.patient_name, &p.patient_id, &p.study_id, &p.study_description,
                                &p.accession_number, &p.referring_physician_name}) {
        std::string utf8;
        if (!detail::to_utf8(*text, charset, utf8)) {
          all_converted = false;
          break;
        }
        *text = utf8;
      }
      // The copied text attributes likewise (a sequence's nested text is kept: codes).
      for (auto it = raw->elements.Begin(); all_converted && it != raw->elements.End(); ++it) {
        const gdcm::VR vr = it->GetVR();
        const gdcm::ByteValue* bv = it->GetByteValue();
        if (!bv || !(vr & (gdcm::VR::PN | gdcm::VR::LO | gdcm::VR::SH | gdcm::VR::LT |
                           gdcm::VR::ST | gdcm::VR::UT | gdcm::VR::UC)))
          continue;
        std::string utf8;
        if (!detail::to_utf8(std::string(bv->GetPointer(), bv->GetLength()), charset, utf8)) {
          all_converted = false;
          break;
        }
        gdcm::DataElement de = *it;
        if (utf8.size() % 2) utf8 += ' ';
        de.SetByteValue(utf8.data(), static_cast<uint32_t>(utf8.size()));
        converted->elements.Replace(de);
      }
      if (all_converted) {
        p.other_attributes = converted;
      } else {  // a set it cannot convert (ISO 2022 code extensions): kept, with that set
        p = as_read;
        p.specific_character_set = charset;
        p.other_attributes = raw;
      }
    }
  }
  progress.update(static_cast<long long>(slices.size()));
  return series;
}

}  // namespace organfit::dicom
