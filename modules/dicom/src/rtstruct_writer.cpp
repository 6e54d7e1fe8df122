#include "organfit/dicom/rtstruct_writer.h"

#include <fmt/format.h>
#include <gdcmWriter.h>

#include "dicom_writing.h"
#include "organfit/support/error.h"

namespace fs = std::filesystem;

namespace organfit::dicom {
namespace {

constexpr const char* kRtstructClass = "1.2.840.10008.5.1.4.1.1.481.3";
constexpr const char* kStudyComponentClass =
    "1.2.840.10008.3.1.2.3.1";  // Detached Study Management (retired, as used by TPS)

using detail::ds_number;
using detail::new_item;
using detail::put;
using detail::put_sequence;

}  // namespace

void write_rtstruct(const fs::path& file, const CtSeries& ct, const std::vector<RtstructRoi>& rois,
                    const RtstructWriteOptions& options) {
  const std::string where = file.string();
  // UIDs: new under one root per run, or derived deterministically (tests).
  const bool fixed = options.fixed_uids_and_dates;
  auto uid = [&](const std::string& what) {
    return detail::make_uid(fixed, ct.series_instance_uid + "|" + what);
  };
  const std::string date = detail::today_da(fixed), time = detail::now_tm(fixed);
  const std::string sop_uid = uid("sop"), series_uid = uid("series");

  gdcm::Writer writer;
  gdcm::DataSet& ds = writer.GetFile().GetDataSet();
  using V = gdcm::VR;
  // SOP Common, Patient, General Study, RT Series, General Equipment.
  detail::put_derived_object_header(ds, ct.patient, date, time);
  put(ds, 0x0008, 0x0016, V::UI, kRtstructClass);
  put(ds, 0x0008, 0x0018, V::UI, sop_uid);
  put(ds, 0x0008, 0x0060, V::CS, "RTSTRUCT");
  put(ds, 0x0008, 0x0070, V::LO, "organfit");
  put(ds, 0x0008, 0x1070, V::PN, "");  // Operators' Name (RT Series, Type 2)
  put(ds, 0x0008, 0x103e, V::LO, options.series_description);
  put(ds, 0x0018, 0x1020, V::LO, "organfit");
  put(ds, 0x0020, 0x000e, V::UI, series_uid);
  put(ds, 0x0020, 0x0011, V::IS, "1");
  put(ds, 0x0020, 0x0052, V::UI, ct.frame_of_reference_uid);  // Frame of Reference at the top level
  put(ds, 0x0020, 0x1040, V::LO, "");  // Position Reference Indicator (Type 2)
  // Structure Set module.
  put(ds, 0x3006, 0x0002, V::SH, options.label);
  put(ds, 0x3006, 0x0008, V::DA, date);
  put(ds, 0x3006, 0x0009, V::TM, time);

  std::vector<gdcm::Item> contour_images;
  for (const auto& slice : ct.slices)
    contour_images.push_back(detail::slice_reference(slice));
  gdcm::Item series_item = new_item();
  put(series_item.GetNestedDataSet(), 0x0020, 0x000e, V::UI, ct.series_instance_uid);
  put_sequence(series_item.GetNestedDataSet(), 0x3006, 0x0016, contour_images);
  gdcm::Item study_item = new_item();
  put(study_item.GetNestedDataSet(), 0x0008, 0x1150, V::UI, kStudyComponentClass);
  put(study_item.GetNestedDataSet(), 0x0008, 0x1155, V::UI, ct.patient.study_instance_uid);
  put_sequence(study_item.GetNestedDataSet(), 0x3006, 0x0014, {series_item});
  gdcm::Item frame_item = new_item();
  put(frame_item.GetNestedDataSet(), 0x0020, 0x0052, V::UI, ct.frame_of_reference_uid);
  put_sequence(frame_item.GetNestedDataSet(), 0x3006, 0x0012, {study_item});
  put_sequence(ds, 0x3006, 0x0010, {frame_item});

  std::vector<gdcm::Item> roi_items, contour_items, observation_items;
  for (size_t r = 0; r < rois.size(); ++r) {
    const RtstructRoi& roi = rois[r];
    const std::string number = std::to_string(r + 1);
    gdcm::Item roi_item = new_item();
    gdcm::DataSet& rds = roi_item.GetNestedDataSet();
    put(rds, 0x3006, 0x0022, V::IS, number);
    put(rds, 0x3006, 0x0024, V::UI, ct.frame_of_reference_uid);
    put(rds, 0x3006, 0x0026, V::LO, roi.name);
    put(rds, 0x3006, 0x0036, V::CS, roi.generation_algorithm);
    roi_items.push_back(roi_item);

    std::vector<gdcm::Item> contours;
    for (size_t c = 0; c < roi.contours.size(); ++c) {
      const auto& contour = roi.contours[c];
      if (contour.k < 0 || contour.k >= static_cast<int>(ct.slices.size()))
        throw InputError(fmt::format("{}: contour {} of ROI '{}' is on no slice of the CT", where,
                                     c + 1, roi.name));
      gdcm::Item item = new_item();
      gdcm::DataSet& cds = item.GetNestedDataSet();
      put_sequence(cds, 0x3006, 0x0016,
                   {detail::slice_reference(ct.slices[static_cast<size_t>(contour.k)])});
      put(cds, 0x3006, 0x0042, V::CS, "CLOSED_PLANAR");
      put(cds, 0x3006, 0x0046, V::IS, std::to_string(contour.points_mm.size()));
      put(cds, 0x3006, 0x0048, V::IS, std::to_string(c + 1));
      std::string data;
      for (const auto& p : contour.points_mm)
        for (int d = 0; d < 3; ++d)
          data += (data.empty() ? "" : "\\") + ds_number(p[d]);
      if (data.size() > 65534)
        throw InputError(
            fmt::format("{}: contour {} of ROI '{}' needs {} bytes, over the DICOM limit of 65,534",
                        where, c + 1, roi.name, data.size()));
      put(cds, 0x3006, 0x0050, V::DS, data);
      contours.push_back(item);
    }
    gdcm::Item contour_item = new_item();
    gdcm::DataSet& ods = contour_item.GetNestedDataSet();
    put(ods, 0x3006, 0x002a, V::IS,
        fmt::format("{}\\{}\\{}", roi.colour[0], roi.colour[1], roi.colour[2]));
    put_sequence(ods, 0x3006, 0x0040, contours);
    put(ods, 0x3006, 0x0084, V::IS, number);
    contour_items.push_back(contour_item);

    gdcm::Item observation = new_item();
    gdcm::DataSet& obs = observation.GetNestedDataSet();
    put(obs, 0x3006, 0x0082, V::IS, number);
    put(obs, 0x3006, 0x0084, V::IS, number);
    put(obs, 0x3006, 0x00a4, V::CS, roi.interpreted_type);
    put(obs, 0x3006, 0x00a6, V::PN, "");
    observation_items.push_back(observation);
  }
  put_sequence(ds, 0x3006, 0x0020, roi_items);
  put_sequence(ds, 0x3006, 0x0039, contour_items);
  put_sequence(ds, 0x3006, 0x0080, observation_items);
  // RT Series / Approval.
  put(ds, 0x300e, 0x0002, V::CS, "UNAPPROVED");

  detail::write_explicit_vr(writer, file, "structure set");
}

}  // namespace organfit::dicom
