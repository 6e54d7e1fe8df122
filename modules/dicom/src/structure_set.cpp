#include "organfit/dicom/structure_set.h"

#include <fmt/format.h>
#include <gdcmDataSet.h>
#include <gdcmReader.h>
#include <gdcmSequenceOfItems.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <map>
#include <sstream>

#include "dicom_values.h"
#include "organfit/support/error.h"
#include "organfit/support/interrupt.h"

namespace fs = std::filesystem;

namespace organfit::dicom {
namespace {

std::string text(const gdcm::DataSet& ds, uint16_t group, uint16_t element) {
  const gdcm::Tag tag(group, element);
  if (!ds.FindDataElement(tag)) return {};
  const gdcm::DataElement& de = ds.GetDataElement(tag);
  const gdcm::ByteValue* bv = de.GetByteValue();
  if (!bv) return {};
  std::string s(bv->GetPointer(), bv->GetLength());
  const auto b = s.find_first_not_of(std::string(" \0", 2));
  const auto e = s.find_last_not_of(std::string(" \0", 2));
  return b == std::string::npos ? std::string() : s.substr(b, e - b + 1);
}

gdcm::SmartPointer<gdcm::SequenceOfItems> sequence(const gdcm::DataSet& ds, uint16_t group,
                                                   uint16_t element) {
  const gdcm::Tag tag(group, element);
  if (!ds.FindDataElement(tag)) return nullptr;
  return ds.GetDataElement(tag).GetValueAsSQ();
}

using detail::numbers;

}  // namespace

const Roi* StructureSet::find(const std::string& name) const {
  for (const auto& r : rois)
    if (r.name == name) return &r;
  return nullptr;
}

std::vector<const Roi*> StructureSet::rois_named(const std::string& name) const {
  std::vector<const Roi*> out;
  for (const auto& r : rois)
    if (r.name == name) out.push_back(&r);
  return out;
}

const Roi* StructureSet::find_number(int number) const {
  for (const auto& r : rois)
    if (r.number == number) return &r;
  return nullptr;
}

StructureSet read_rtstruct(const fs::path& file) {
  const std::string where = file.string();
  detail::quiet_gdcm();
  if (!detail::safe_for_gdcm(where))
    throw InputError(where + ": cannot read as DICOM (missing, truncated or not DICOM)");
  gdcm::Reader reader;
  reader.SetFileName(where.c_str());
  bool read_ok = false;
  {
    ReadingInput guard(where.c_str(), "GDCM");
    read_ok = reader.Read();
  }
  if (!read_ok)
    throw InputError(where + ": cannot read as DICOM (missing, truncated or not DICOM)");
  const gdcm::DataSet& ds = reader.GetFile().GetDataSet();
  if (text(ds, 0x0008, 0x0060) != "RTSTRUCT")
    throw InputError(where + ": not an RT Structure Set (Modality '" + text(ds, 0x0008, 0x0060) +
                     "')");
  StructureSet rtss;
  rtss.patient_id = text(ds, 0x0010, 0x0020);
  if (std::string utf8; detail::to_utf8(rtss.patient_id, text(ds, 0x0008, 0x0005), utf8))
    rtss.patient_id = utf8;  // compared with the CT's, which is UTF-8 too
  rtss.study_instance_uid = text(ds, 0x0020, 0x000d);
  if (auto sq = sequence(ds, 0x3006, 0x0010); sq && sq->GetNumberOfItems() > 0) {
    rtss.referenced_frame_of_reference_uid =
        text(sq->GetItem(1).GetNestedDataSet(), 0x0020, 0x0052);
    // Frame of Reference > RT Referenced Study (3006,0012) > RT Referenced Series (3006,0014).
    for (size_t f = 1; f <= sq->GetNumberOfItems(); ++f)
      if (auto studies = sequence(sq->GetItem(f).GetNestedDataSet(), 0x3006, 0x0012))
        for (size_t s = 1; s <= studies->GetNumberOfItems(); ++s)
          if (auto series = sequence(studies->GetItem(s).GetNestedDataSet(), 0x3006, 0x0014))
            for (size_t e = 1; e <= series->GetNumberOfItems(); ++e)
              if (std::string uid = text(series->GetItem(e).GetNestedDataSet(), 0x0020, 0x000e);
                  !uid.empty())
                rtss.referenced_series_uids.push_back(std::move(uid));
  }
  std::map<int, Roi> by_number;
  if (auto sq = sequence(ds, 0x3006, 0x0020)) {  // Structure Set ROI Sequence
    for (size_t i = 1; i <= sq->GetNumberOfItems(); ++i) {
      const gdcm::DataSet& item = sq->GetItem(i).GetNestedDataSet();
      Roi roi;
      roi.number = std::atoi(text(item, 0x3006, 0x0022).c_str());
      roi.name = text(item, 0x3006, 0x0026);
      roi.frame_of_reference_uid = text(item, 0x3006, 0x0024);
      by_number[roi.number] = roi;
    }
  }
  if (auto sq = sequence(ds, 0x3006, 0x0039)) {  // ROI Contour Sequence
    for (size_t i = 1; i <= sq->GetNumberOfItems(); ++i) {
      const gdcm::DataSet& item = sq->GetItem(i).GetNestedDataSet();
      const int number = std::atoi(text(item, 0x3006, 0x0084).c_str());
      Roi& roi = by_number[number];
      roi.number = number;
      const std::vector<double> colour = numbers(text(item, 0x3006, 0x002a));
      // Only a real colour is taken (a NaN cast to int is undefined: found by fuzzing).
      if (colour.size() == 3 &&
          std::all_of(colour.begin(), colour.end(), [](double v) { return v >= 0 && v <= 255; }))
        for (int c = 0; c < 3; ++c)
          roi.colour[c] = static_cast<int>(colour[c]);
      auto contours = sequence(item, 0x3006, 0x0040);
      if (!contours) continue;
      for (size_t c = 1; c <= contours->GetNumberOfItems(); ++c) {
        const gdcm::DataSet& cds = contours->GetItem(c).GetNestedDataSet();
        Contour contour;
        contour.geometric_type = text(cds, 0x3006, 0x0042);
        if (auto images = sequence(cds, 0x3006, 0x0016); images && images->GetNumberOfItems() > 0)
          contour.referenced_sop_instance_uid =
              text(images->GetItem(1).GetNestedDataSet(), 0x0008, 0x1155);
        const std::vector<double> xyz = numbers(text(cds, 0x3006, 0x0050));
        contour.value_count = static_cast<long>(xyz.size());
        const std::string declared = text(cds, 0x3006, 0x0046);
        if (!declared.empty()) contour.declared_points = std::atol(declared.c_str());
        for (size_t p = 0; p + 2 < xyz.size(); p += 3)
          contour.points_mm.emplace_back(xyz[p], xyz[p + 1], xyz[p + 2]);
        roi.contours.push_back(std::move(contour));
      }
    }
  }
  if (auto sq = sequence(ds, 0x3006, 0x0080)) {  // RT ROI Observations Sequence
    for (size_t i = 1; i <= sq->GetNumberOfItems(); ++i) {
      const gdcm::DataSet& item = sq->GetItem(i).GetNestedDataSet();
      const auto it = by_number.find(std::atoi(text(item, 0x3006, 0x0084).c_str()));
      if (it != by_number.end()) it->second.interpreted_type = text(item, 0x3006, 0x00a4);
    }
  }
  for (auto& [number, roi] : by_number)
    rtss.rois.push_back(std::move(roi));
  if (!rtss.rois.empty()) rtss.frame_of_reference_uid = rtss.rois.front().frame_of_reference_uid;
  return rtss;
}

namespace {

enum class Placement { kNone, kByReference, kByPosition };

/// The CT slice a contour lies on: the one its Referenced SOP Instance UID names when its
/// mean position along the normal is within kContourSliceTolerance of it, else the slice
/// at that position (within the same tolerance); -1 when none.
int slice_of_contour(const Contour& contour, const CtSeries& ct,
                     const std::map<std::string, int>& slice_of_uid, Placement& how) {
  how = Placement::kNone;
  if (contour.points_mm.empty()) return -1;
  double k_sum = 0;
  for (const auto& p : contour.points_mm)
    k_sum += ct.geometry.physical_to_index(p).z();
  const double k = k_sum / static_cast<double>(contour.points_mm.size());
  if (!std::isfinite(k)) return -1;
  const auto it = slice_of_uid.find(contour.referenced_sop_instance_uid);
  if (it != slice_of_uid.end() && std::abs(k - it->second) <= kContourSliceTolerance) {
    how = Placement::kByReference;
    return it->second;
  }
  const long nearest = std::lround(k);
  if (nearest < 0 || nearest >= ct.geometry.size[2] ||
      std::abs(k - nearest) > kContourSliceTolerance)
    return -1;
  how = Placement::kByPosition;
  return static_cast<int>(nearest);
}

/// Whether a polygon's points all lie within `tolerance` of one line: it encloses no area.
/// (Its signed area would also be zero for a figure eight whose lobes are alike, which
/// does enclose some.)
bool encloses_no_area(const std::vector<Eigen::Vector2d>& poly, double tolerance) {
  if (poly.empty()) return true;
  const Eigen::Vector2d& p0 = poly.front();
  Eigen::Vector2d far = p0;
  for (const auto& p : poly)
    if ((p - p0).squaredNorm() > (far - p0).squaredNorm()) far = p;
  const Eigen::Vector2d along = far - p0;
  if (!(along.norm() > tolerance)) return true;
  const Eigen::Vector2d unit = along / along.norm();
  for (const auto& p : poly) {
    const Eigen::Vector2d d = p - p0;
    if (std::abs(unit.x() * d.y() - unit.y() * d.x()) > tolerance) return false;
  }
  return true;
}

/// Where a closed polygon's edges (continuous index) cross row y: x, and +1 for an edge
/// going up, -1 down, appended to `out`. An edge crosses when one end lies on or below y and
/// the other above it.
void row_crossings(const std::vector<Eigen::Vector2d>& poly, double y,
                   std::vector<std::pair<double, int>>& out) {
  for (size_t e = 0; e < poly.size(); ++e) {
    const Eigen::Vector2d& a = poly[e];
    const Eigen::Vector2d& b = poly[(e + 1) % poly.size()];
    if ((a.y() <= y) == (b.y() <= y)) continue;
    out.emplace_back(a.x() + (y - a.y()) * (b.x() - a.x()) / (b.y() - a.y()),
                     b.y() > a.y() ? 1 : -1);
  }
}

/// The voxel centres of an nx x ny slice (index (i, j) at i + nx j) that the polygons (in
/// continuous index) enclose by the even-odd rule, as `set(i, j)` calls, row by row.
template <class Set>
void fill_even_odd(const std::vector<const std::vector<Eigen::Vector2d>*>& polys, int nx, int ny,
                   Set&& set) {
  std::vector<std::pair<double, int>> crossings;
  for (int j = 0; j < ny; ++j) {
    crossings.clear();
    for (const auto* poly : polys)
      row_crossings(*poly, j, crossings);
    // Pairs of the sorted crossings of all contours: the even-odd rule (holes, islands).
    std::sort(crossings.begin(), crossings.end());
    for (size_t c = 0; c + 1 < crossings.size(); c += 2) {
      const int i0 = std::max(0, static_cast<int>(std::ceil(crossings[c].first)));
      const int i1 = std::min(nx - 1, static_cast<int>(std::floor(crossings[c + 1].first)));
      for (int i = i0; i <= i1; ++i)
        set(i, j);
    }
  }
}

/// The voxel centres of an nx x ny slice around which a closed polygon (in continuous
/// index) winds an even number of times other than zero: where it overlaps itself, and
/// where the even-odd rule would read a hole the contour does not draw. A simple polygon,
/// or a figure eight (its lobes wound once each way), has none.
long long voxels_wound_twice(const std::vector<Eigen::Vector2d>& poly, int nx, int ny) {
  double y_lo = HUGE_VAL, y_hi = -HUGE_VAL;
  for (const auto& v : poly)
    y_lo = std::min(y_lo, v.y()), y_hi = std::max(y_hi, v.y());
  long long count = 0;
  std::vector<std::pair<double, int>> crossings;
  const int j_lo = std::max(0, static_cast<int>(std::ceil(y_lo)));
  const int j_hi = std::min(ny - 1, static_cast<int>(std::floor(y_hi)));
  for (int j = j_lo; j <= j_hi; ++j) {
    crossings.clear();
    row_crossings(poly, j, crossings);
    std::sort(crossings.begin(), crossings.end());
    int winding = 0;
    for (size_t c = 0; c + 1 < crossings.size(); ++c) {
      winding += crossings[c].second;
      if (winding == 0 || winding % 2 != 0) continue;
      const int i0 = std::max(0, static_cast<int>(std::ceil(crossings[c].first)));
      const int i1 = std::min(nx - 1, static_cast<int>(std::floor(crossings[c + 1].first)));
      count += std::max(0, i1 - i0 + 1);
    }
  }
  return count;
}

/// True when a contour's Contour Data holds 3 values per declared point.
bool value_count_agrees(const Contour& c) {
  return c.declared_points < 0 ? c.value_count % 3 == 0 : c.value_count == 3 * c.declared_points;
}

std::map<std::string, int> slices_by_uid(const CtSeries& ct) {
  std::map<std::string, int> slice_of_uid;
  for (size_t s = 0; s < ct.slices.size(); ++s)
    slice_of_uid[ct.slices[s].sop_instance_uid] = static_cast<int>(s);
  return slice_of_uid;
}

}  // namespace

RoiOnSlices roi_on_slices(const Roi& roi, const CtSeries& ct) {
  RoiOnSlices out;
  const auto slice_of_uid = slices_by_uid(ct);
  for (const auto& contour : roi.contours) {
    Placement how = Placement::kNone;
    const bool usable = contour.geometric_type == "CLOSED_PLANAR" &&
                        contour.points_mm.size() >= 3 && value_count_agrees(contour);
    const int k = usable ? slice_of_contour(contour, ct, slice_of_uid, how) : -1;
    std::vector<Eigen::Vector2d> poly;
    for (const auto& p : contour.points_mm)
      poly.emplace_back(p.x(), p.y());
    if (k < 0 || encloses_no_area(poly, 0.0)) {
      ++out.skipped;
      continue;
    }
    out.matched_by_position += how == Placement::kByPosition;
    geometry::SliceContour c;
    c.k = k;
    c.points_mm = contour.points_mm;
    out.contours.push_back(std::move(c));
  }
  return out;
}

void check_structure_set_matches_ct(const StructureSet& rtss, const Roi& roi, const CtSeries& ct,
                                    const std::string& source) {
  const std::string ct_name = ct.folder.empty() ? std::string("the CT") : ct.folder.string();
  auto fail = [&](const std::string& why) {
    throw InputError(
        fmt::format("{}: {} ({}): not a structure set of this CT", source, why, ct_name));
  };
  if (!rtss.patient_id.empty() && !ct.patient.patient_id.empty() &&
      rtss.patient_id != ct.patient.patient_id)
    fail("its Patient ID differs from the CT's");
  if (!rtss.study_instance_uid.empty() && !ct.patient.study_instance_uid.empty() &&
      rtss.study_instance_uid != ct.patient.study_instance_uid)
    fail("its Study Instance UID differs from the CT's");
  const std::string& frame = !roi.frame_of_reference_uid.empty()
                                 ? roi.frame_of_reference_uid
                                 : rtss.referenced_frame_of_reference_uid;
  if (!frame.empty() && frame != ct.frame_of_reference_uid)
    fail(fmt::format("ROI '{}' is in another Frame of Reference than the CT", echo(roi.name)));
  if (frame.empty()) {
    const auto slice_of_uid = slices_by_uid(ct);
    for (const auto& c : roi.contours)
      if (!slice_of_uid.count(c.referenced_sop_instance_uid))
        fail(fmt::format(
            "it names no Frame of Reference and ROI '{}' has contours that reference no slice of "
            "the CT",
            echo(roi.name)));
  }
}

const Roi& choose_roi(const StructureSet& rtss, const std::string& name, int roi_number,
                      const std::string& source) {
  auto fail = [&](const std::string& why) { throw InputError(source + ": " + why); };
  auto names = [&]() {
    std::string list;
    for (const auto& r : rtss.rois)
      list += (list.empty() ? "" : ", ") + ("'" + echo(r.name, 40) + "'");
    return list.empty() ? std::string("none") : echo(list, 400);
  };
  if (roi_number > 0) {
    const Roi* roi = rtss.find_number(roi_number);
    if (!roi) fail(fmt::format("no ROI number {} (the structure set has {})", roi_number, names()));
    if (!name.empty() && roi->name != name)
      fail(fmt::format("ROI number {} is named '{}', not '{}'", roi_number, echo(roi->name),
                       echo(name)));
    return *roi;
  }
  const std::vector<const Roi*> named = rtss.rois_named(name);
  if (named.empty())
    fail(fmt::format("no ROI named '{}' (the structure set has {})", echo(name), names()));
  if (named.size() > 1) {
    std::string numbers;
    for (const Roi* r : named)
      numbers += (numbers.empty() ? "" : ", ") + std::to_string(r->number);
    fail(
        fmt::format("{} ROIs are named '{}' (ROI numbers {}): choose one by its number "
                    "(organ.roi_number, or segment --roi-number)",
                    named.size(), echo(name), numbers));
  }
  return *named.front();
}

RasterisedRoi rasterise_roi(const StructureSet& rtss, const std::string& name, const CtSeries& ct,
                            const std::string& source, int roi_number) {
  auto fail = [&](const std::string& why) { throw InputError(source + ": " + why); };
  const Roi* roi = &choose_roi(rtss, name, roi_number, source);
  const std::string shown = echo(roi->name);
  check_structure_set_matches_ct(rtss, *roi, ct, source);
  if (roi->contours.empty()) fail(fmt::format("ROI '{}' has no contours", shown));

  const geometry::ImageGeometry& g = ct.geometry;
  RasterisedRoi out;
  out.mask = geometry::LabelVolume(g);
  out.colour = roi->colour;
  out.interpreted_type = roi->interpreted_type;
  const auto slice_of_uid = slices_by_uid(ct);

  // Group each contour's polygon (in continuous i, j index) under its slice, with its number
  // (1-based, as errors name it).
  struct Polygon {
    size_t number = 0;
    std::vector<Eigen::Vector2d> vertices;
  };
  std::vector<std::vector<Polygon>> polygons(g.size[2]);
  int placed = 0;
  for (size_t c = 0; c < roi->contours.size(); ++c) {
    const Contour& contour = roi->contours[c];
    const std::string which = fmt::format("ROI '{}' contour {}", shown, c + 1);
    if (contour.geometric_type != "CLOSED_PLANAR")
      fail(fmt::format(
          "{} is {} (a volume needs CLOSED_PLANAR contours)", which,
          contour.geometric_type.empty() ? "of no type" : echo(contour.geometric_type)));
    if (!value_count_agrees(contour))
      fail(fmt::format("{}: its Contour Data has {} values, not 3 x Number of Contour Points ({})",
                       which, contour.value_count, contour.declared_points));
    std::vector<Eigen::Vector2d> poly;
    for (const auto& p : contour.points_mm) {
      if (!p.allFinite()) fail(which + " has a non-finite coordinate");
      const Eigen::Vector3d idx = g.physical_to_index(p);
      poly.emplace_back(idx.x(), idx.y());
    }
    Placement how = Placement::kNone;
    const int slice = slice_of_contour(contour, ct, slice_of_uid, how);
    const double along =
        contour.points_mm.empty() ? 0.0 : g.direction.col(2).dot(contour.points_mm.front());
    const std::string on_slice = slice >= 0 ? fmt::format("on slice {} (z {:.2f} mm)", slice, along)
                                            : fmt::format("at z {:.2f} mm", along);
    // Degenerate contours carry no area: skipped, as plastimatch does, the organ kept.
    if (contour.points_mm.size() < 3 || encloses_no_area(poly, 1e-9)) {
      out.warnings.push_back(
          fmt::format("{}: {} {} {}: skipped", source, which, on_slice,
                      contour.points_mm.size() < 3
                          ? fmt::format("has {} point(s), fewer than 3", contour.points_mm.size())
                          : std::string("has zero area")));
      ++out.skipped;
      continue;
    }
    if (slice < 0)
      fail(
          fmt::format("{} lies on no slice of the CT (at {:.2f} mm along the slice normal, more "
                      "than {} slice gap from the nearest)",
                      which, along, kContourSliceTolerance));
    // CLOSED_PLANAR: every point on the slice it is placed on, not only their mean.
    double farthest = 0;
    for (const auto& p : contour.points_mm)
      farthest = std::max(farthest, std::abs(g.physical_to_index(p).z() - slice));
    if (farthest > kContourSliceTolerance)
      fail(fmt::format(
          "{} {} is not planar: a point of it lies {:.2f} mm off that slice (more than {} slice "
          "gap)",
          which, on_slice, farthest * g.spacing_mm.z(), kContourSliceTolerance));
    if (const long long twice = voxels_wound_twice(poly, g.size[0], g.size[1]); twice > 0)
      fail(fmt::format(
          "{} {} crosses itself and winds twice around {} voxel(s): read by the even-odd rule "
          "they would be a hole it does not draw",
          which, on_slice, twice));
    if (how == Placement::kByPosition) ++out.matched_by_position;
    const auto [xmin, xmax] = std::minmax_element(poly.begin(), poly.end(),
                                                  [](auto& a, auto& b) { return a.x() < b.x(); });
    const auto [ymin, ymax] = std::minmax_element(poly.begin(), poly.end(),
                                                  [](auto& a, auto& b) { return a.y() < b.y(); });
    if (xmax->x() < -0.5 || ymax->y() < -0.5 || xmin->x() > g.size[0] - 0.5 ||
        ymin->y() > g.size[1] - 0.5)
      fail(which + " lies outside the image");
    polygons[slice].push_back({c + 1, std::move(poly)});
    ++placed;
  }
  out.contours = placed;
  if (placed == 0)
    fail(
        fmt::format("ROI '{}' has no usable contour ({} skipped: fewer than 3 points or zero area)",
                    shown, out.skipped));
  // A slice without a contour between contoured ones: the organ is read with that gap (a
  // slice left out in contouring, or a contour skipped above), said with the slices.
  {
    std::vector<int> gaps;
    int first = g.size[2], last = -1;
    for (int k = 0; k < g.size[2]; ++k)
      if (!polygons[k].empty()) first = std::min(first, k), last = k;
    for (int k = first + 1; k < last; ++k)
      if (polygons[k].empty()) gaps.push_back(k);
    if (!gaps.empty()) {
      std::string named;
      for (size_t n = 0; n < gaps.size() && n < 5; ++n)
        named += fmt::format("{}{} (z {:.2f} mm)", n ? ", " : "", gaps[n],
                             g.direction.col(2).dot(g.index_to_physical(
                                 Eigen::Vector3d(0, 0, static_cast<double>(gaps[n])))));
      out.warnings.push_back(fmt::format(
          "{}: ROI '{}' has no contour on {} slice(s) between its first and last ({}{}): read "
          "with {} (a slice left out in contouring?)",
          source, shown, gaps.size(), named, gaps.size() > 5 ? ", ..." : "",
          gaps.size() == 1 ? "that gap" : "those gaps"));
    }
  }
  if (out.matched_by_position > 0)
    out.warnings.push_back(
        fmt::format("{}: {} of {} contours of ROI '{}' reference no slice of this series that they "
                    "lie on; matched by position",
                    source, out.matched_by_position, out.contours, shown));

  // A slice's contours are read together by the even-odd rule, meant for contours apart or
  // nested (a contour within another is a hole). Each contour's voxels alone, pair by pair:
  // the same voxels twice (a contour exported twice) would cancel each other and take that
  // slice's part of the organ away: read once, said. Voxels partly shared (contours that
  // overlap, neither apart nor nested) would have their overlap cut out, and which area they
  // mean cannot be told: refused.
  const int nx = g.size[0], ny = g.size[1];
  for (int k = 0; k < g.size[2]; ++k) {
    std::vector<Polygon>& on_slice = polygons[k];
    if (on_slice.size() < 2) continue;
    struct Voxels {
      std::vector<std::uint8_t> in;  // nx x ny
      long long count = 0;
      int i0 = std::numeric_limits<int>::max(), i1 = -1, j0 = std::numeric_limits<int>::max(),
          j1 = -1;  // the box of the voxels in it
    };
    std::vector<Voxels> alone;
    for (const auto& p : on_slice) {
      Voxels& v = alone.emplace_back();
      v.in.assign(static_cast<size_t>(nx) * ny, 0);
      fill_even_odd({&p.vertices}, nx, ny, [&](int i, int j) {
        std::uint8_t& here = v.in[static_cast<size_t>(i + nx * j)];
        v.count += here == 0;  // a voxel at two intervals' shared end is one voxel
        here = 1;
        v.i0 = std::min(v.i0, i), v.i1 = std::max(v.i1, i);
        v.j0 = std::min(v.j0, j), v.j1 = std::max(v.j1, j);
      });
    }
    for (size_t a = 0; a < on_slice.size(); ++a)
      for (size_t b = a + 1; b < on_slice.size();) {
        const long long in_a = alone[a].count, in_b = alone[b].count;
        // The voxels both hold lie in both boxes: a slice of many small contours (islands)
        // compares each pair over their boxes' common part, not the whole slice.
        long long shared = 0;
        const Voxels &va = alone[a], &vb = alone[b];
        for (int j = std::max(va.j0, vb.j0); j <= std::min(va.j1, vb.j1); ++j)
          for (int i = std::max(va.i0, vb.i0); i <= std::min(va.i1, vb.i1); ++i) {
            const size_t v = static_cast<size_t>(i + nx * j);
            shared += va.in[v] & vb.in[v];
          }
        if (shared > 0 && shared == in_a && shared == in_b) {
          out.warnings.push_back(fmt::format(
              "{}: ROI '{}' contour {} encloses the same voxels as contour {} on slice {} (a "
              "contour exported twice?): read once",
              source, shown, on_slice[b].number, on_slice[a].number, k));
          on_slice.erase(on_slice.begin() + static_cast<long>(b));
          alone.erase(alone.begin() + static_cast<long>(b));
          continue;
        }
        if (shared > 0 && shared < in_a && shared < in_b)
          fail(fmt::format(
              "ROI '{}' contours {} and {} on slice {} overlap: neither apart nor one within "
              "the other, so the area they mean cannot be told (read together by the even-odd "
              "rule, the {} voxels they share would be cut out)",
              shown, on_slice[a].number, on_slice[b].number, k, shared));
        ++b;
      }
  }

  // The even-odd fill per slice, over all the slice's contours together.
  for (int k = 0; k < g.size[2]; ++k) {
    if (polygons[k].empty()) continue;
    std::vector<const std::vector<Eigen::Vector2d>*> polys;
    for (const auto& p : polygons[k])
      polys.push_back(&p.vertices);
    fill_even_odd(polys, nx, ny, [&](int i, int j) { out.mask.at(i, j, k) = 1; });
  }
  return out;
}

}  // namespace organfit::dicom
