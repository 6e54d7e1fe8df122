#include "organfit/dicom/structure_set.h"

#include <fmt/format.h>
#include <gdcmDataSet.h>
#include <gdcmReader.h>
#include <gdcmSequenceOfItems.h>

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
        for (size_t p = 0; p + 2 < xyz.size(); p += 3)
          contour.points_mm.emplace_back(xyz[p], xyz[p + 1], xyz[p + 2]);
        roi.contours.push_back(std::move(contour));
      }
    }
  }
  for (auto& [number, roi] : by_number)
    rtss.rois.push_back(std::move(roi));
  if (!rtss.rois.empty()) rtss.frame_of_reference_uid = rtss.rois.front().frame_of_reference_uid;
  return rtss;
}

namespace {

/// The CT slice a contour lies on: the one its Referenced SOP Instance UID names, else
/// the slice at its mean position along the normal (within a tenth of the slice gap);
/// -1 when none.
int slice_of_contour(const Contour& contour, const CtSeries& ct,
                     const std::map<std::string, int>& slice_of_uid, bool& by_position) {
  by_position = false;
  const auto it = slice_of_uid.find(contour.referenced_sop_instance_uid);
  if (it != slice_of_uid.end()) return it->second;
  if (contour.points_mm.empty()) return -1;
  double k_sum = 0;
  for (const auto& p : contour.points_mm)
    k_sum += ct.geometry.physical_to_index(p).z();
  const double k = k_sum / static_cast<double>(contour.points_mm.size());
  const long nearest = std::lround(k);
  if (!std::isfinite(k) || nearest < 0 || nearest >= ct.geometry.size[2] ||
      std::abs(k - nearest) > 0.1)
    return -1;
  by_position = true;
  return static_cast<int>(nearest);
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
    bool by_position = false;
    const int k = contour.geometric_type == "CLOSED_PLANAR" && contour.points_mm.size() >= 3
                      ? slice_of_contour(contour, ct, slice_of_uid, by_position)
                      : -1;
    if (k < 0) {
      ++out.skipped;
      continue;
    }
    out.matched_by_position += by_position;
    geometry::SliceContour c;
    c.k = k;
    c.points_mm = contour.points_mm;
    out.contours.push_back(std::move(c));
  }
  return out;
}

RasterisedRoi rasterise_roi(const StructureSet& rtss, const std::string& name, const CtSeries& ct,
                            const std::string& source) {
  auto fail = [&](const std::string& why) { throw InputError(source + ": " + why); };
  const Roi* roi = rtss.find(name);
  if (!roi) {
    std::string names;
    for (const auto& r : rtss.rois)
      names += (names.empty() ? "" : ", ") + ("'" + r.name + "'");
    fail(fmt::format("no ROI named '{}' (the structure set has {})", name,
                     names.empty() ? "none" : names));
  }
  if (!roi->frame_of_reference_uid.empty() &&
      roi->frame_of_reference_uid != ct.frame_of_reference_uid)
    fail(fmt::format("ROI '{}' is in another Frame of Reference than the CT ({} vs {})", name,
                     roi->frame_of_reference_uid, ct.frame_of_reference_uid));
  if (roi->contours.empty()) fail(fmt::format("ROI '{}' has no contours", name));

  const geometry::ImageGeometry& g = ct.geometry;
  RasterisedRoi out;
  out.mask = geometry::LabelVolume(g);
  const auto slice_of_uid = slices_by_uid(ct);

  // Group each contour's polygon (in continuous i, j index) under its slice.
  std::vector<std::vector<std::vector<Eigen::Vector2d>>> polygons(g.size[2]);
  for (size_t c = 0; c < roi->contours.size(); ++c) {
    const Contour& contour = roi->contours[c];
    const std::string which = fmt::format("ROI '{}' contour {}", name, c + 1);
    if (contour.geometric_type != "CLOSED_PLANAR")
      fail(fmt::format("{} is {} (a volume needs CLOSED_PLANAR contours)", which,
                       contour.geometric_type.empty() ? "of no type" : contour.geometric_type));
    if (contour.points_mm.size() < 3)
      fail(fmt::format("{} has {} point(s), fewer than 3", which, contour.points_mm.size()));
    std::vector<Eigen::Vector2d> poly;
    for (const auto& p : contour.points_mm) {
      if (!p.allFinite()) fail(which + " has a non-finite coordinate");
      const Eigen::Vector3d idx = g.physical_to_index(p);
      poly.emplace_back(idx.x(), idx.y());
    }
    bool by_position = false;
    const int slice = slice_of_contour(contour, ct, slice_of_uid, by_position);
    if (slice < 0)
      fail(fmt::format("{} lies on no slice of the CT (at {:.2f} mm along the slice normal)", which,
                       g.direction.col(2).dot(contour.points_mm.front())));
    if (by_position) ++out.matched_by_position;
    const auto [xmin, xmax] = std::minmax_element(poly.begin(), poly.end(),
                                                  [](auto& a, auto& b) { return a.x() < b.x(); });
    const auto [ymin, ymax] = std::minmax_element(poly.begin(), poly.end(),
                                                  [](auto& a, auto& b) { return a.y() < b.y(); });
    if (xmax->x() < -0.5 || ymax->y() < -0.5 || xmin->x() > g.size[0] - 0.5 ||
        ymin->y() > g.size[1] - 0.5)
      fail(which + " lies outside the image");
    polygons[slice].push_back(std::move(poly));
    ++out.contours;
  }
  if (out.matched_by_position > 0)
    out.warnings.push_back(
        fmt::format("{}: {} of {} contours of ROI '{}' reference CT slices that are not in this "
                    "series; matched by position",
                    source, out.matched_by_position, out.contours, name));

  // Even-odd scanline fill per slice, over all the slice's contours together.
  for (int k = 0; k < g.size[2]; ++k) {
    if (polygons[k].empty()) continue;
    std::vector<double> crossings;
    for (int j = 0; j < g.size[1]; ++j) {
      crossings.clear();
      const double y = j;
      for (const auto& poly : polygons[k]) {
        for (size_t e = 0; e < poly.size(); ++e) {
          const Eigen::Vector2d& a = poly[e];
          const Eigen::Vector2d& b = poly[(e + 1) % poly.size()];
          if ((a.y() <= y) == (b.y() <= y)) continue;  // edge does not cross this row
          crossings.push_back(a.x() + (y - a.y()) * (b.x() - a.x()) / (b.y() - a.y()));
        }
      }
      // Pairs of the sorted crossings of all contours: the even-odd rule (holes, islands).
      std::sort(crossings.begin(), crossings.end());
      for (size_t c = 0; c + 1 < crossings.size(); c += 2) {
        const int i0 = std::max(0, static_cast<int>(std::ceil(crossings[c])));
        const int i1 = std::min(g.size[0] - 1, static_cast<int>(std::floor(crossings[c + 1])));
        for (int i = i0; i <= i1; ++i)
          out.mask.at(i, j, k) = 1;
      }
    }
  }
  return out;
}

}  // namespace organfit::dicom
