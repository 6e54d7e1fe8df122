#include "organfit/dicom/ct_writer.h"

#include <fmt/format.h>
#include <gdcmFileMetaInformation.h>
#include <gdcmWriter.h>

#include <algorithm>
#include <cmath>

#include "dicom_values.h"
#include "dicom_writing.h"
#include "organfit/support/atomic_file.h"
#include "organfit/support/error.h"

namespace fs = std::filesystem;

namespace organfit::dicom {
namespace {
constexpr int kIntercept = -1024;  // stored = HU + 1024, 12 bits: HU in [-1024, 3071]
constexpr int kMaxStored = 4095;
}  // namespace

long long write_ct_series(const fs::path& folder, CtSeries& ct, const CtWriteOptions& options) {
  using detail::ds_number;
  using detail::put;
  using V = gdcm::VR;
  const std::string where = folder.string();
  const auto& g = ct.geometry;
  if (g.voxel_count() <= 0 || ct.hu.size() != static_cast<size_t>(g.voxel_count()))
    throw InputError(where + ": the CT has no voxels or its values do not match its size");
  std::error_code ec;
  if (fs::exists(folder, ec))
    throw InputError(where + ": exists already; a CT series is written into a new folder");
  if (!folder.parent_path().empty()) fs::create_directories(folder.parent_path(), ec);

  const bool fixed = options.fixed_uids_and_dates;
  auto uid = [&](const std::string& what) {
    return detail::make_uid(fixed, options.uid_key + "|" + what);
  };
  if (ct.patient.study_instance_uid.empty()) ct.patient.study_instance_uid = uid("study");
  if (ct.series_instance_uid.empty()) ct.series_instance_uid = uid("series");
  if (ct.frame_of_reference_uid.empty()) ct.frame_of_reference_uid = uid("frame");
  const std::string date = detail::today_da(fixed), time = detail::now_tm(fixed);
  if (ct.patient.study_date.empty()) ct.patient.study_date = date;
  if (ct.patient.study_time.empty()) ct.patient.study_time = time;

  TempPath temp(folder);
  fs::create_directory(temp.path(), ec);
  if (ec) throw InputError(where + ": cannot create the folder: " + ec.message());

  const Eigen::Vector3d row_cosines = g.direction.col(0), column_cosines = g.direction.col(1);
  std::string orientation;
  for (int d = 0; d < 3; ++d)
    orientation += (d ? "\\" : "") + ds_number(row_cosines[d]);
  for (int d = 0; d < 3; ++d)
    orientation += "\\" + ds_number(column_cosines[d]);
  const int columns = g.size[0], rows = g.size[1];
  const size_t per_slice = static_cast<size_t>(columns) * static_cast<size_t>(rows);
  long long clipped = 0;
  std::vector<CtSlice> slices;
  std::vector<std::uint16_t> pixels(per_slice);
  for (int k = 0; k < g.size[2]; ++k) {
    CtSlice slice;
    slice.sop_class_uid = detail::kCtImageStorage;
    slice.sop_instance_uid = uid(fmt::format("slice|{}", k));
    slice.position_mm = g.index_to_physical(Eigen::Vector3d(0, 0, k));
    slice.file = folder / fmt::format("CT{:04d}.dcm", k + 1);
    for (size_t v = 0; v < per_slice; ++v) {
      const double stored = std::round(double(ct.hu[k * per_slice + v]) - kIntercept);
      if (!(stored >= 0 && stored <= kMaxStored)) ++clipped;
      pixels[v] = static_cast<std::uint16_t>(
          std::clamp(std::isfinite(stored) ? stored : 0.0, 0.0, double(kMaxStored)));
    }

    gdcm::Writer writer;
    gdcm::DataSet& ds = writer.GetFile().GetDataSet();
    // SOP Common, Patient, General Study.
    put(ds, 0x0008, 0x0005, V::CS,
        ct.patient.specific_character_set.empty() ? "ISO_IR 192"
                                                  : ct.patient.specific_character_set);
    put(ds, 0x0008, 0x0008, V::CS, "ORIGINAL\\PRIMARY\\AXIAL");
    detail::put_patient_study(ds, ct.patient);  // Patient, General Study: verbatim
    put(ds, 0x0008, 0x0016, V::UI, detail::kCtImageStorage);
    put(ds, 0x0008, 0x0018, V::UI, slice.sop_instance_uid);
    put(ds, 0x0008, 0x0021, V::DA, ct.patient.study_date);
    put(ds, 0x0008, 0x0031, V::TM, ct.patient.study_time);
    put(ds, 0x0008, 0x0060, V::CS, "CT");
    put(ds, 0x0008, 0x0070, V::LO, "organfit");
    put(ds, 0x0008, 0x103e, V::LO, ct.series_description);
    put(ds, 0x0008, 0x1090, V::LO, "organfit synthetic phantom");
    // General Series, CT Image, Image Plane.
    if (!options.body_part_examined.empty())
      put(ds, 0x0018, 0x0015, V::CS, options.body_part_examined);
    else
      put(ds, 0x0020, 0x0060, V::CS, "");  // Laterality, Type 2C: unknown when the body part is
    put(ds, 0x0018, 0x0050, V::DS, ds_number(g.spacing_mm[2]));  // Slice Thickness
    put(ds, 0x0018, 0x0060, V::DS, "120");                       // KVP
    put(ds, 0x0018, 0x5100, V::CS, "HFS");                       // Patient Position
    put(ds, 0x0020, 0x000e, V::UI, ct.series_instance_uid);
    put(ds, 0x0020, 0x0011, V::IS, "1");
    put(ds, 0x0020, 0x0012, V::IS, "1");
    put(ds, 0x0020, 0x0013, V::IS, std::to_string(k + 1));
    put(ds, 0x0020, 0x0032, V::DS,
        fmt::format("{}\\{}\\{}", ds_number(slice.position_mm[0]), ds_number(slice.position_mm[1]),
                    ds_number(slice.position_mm[2])));
    put(ds, 0x0020, 0x0037, V::DS, orientation);
    put(ds, 0x0020, 0x0052, V::UI, ct.frame_of_reference_uid);
    put(ds, 0x0020, 0x1040, V::LO, "");
    put(ds, 0x0020, 0x1041, V::DS, ds_number(slice.position_mm.dot(g.direction.col(2))));
    // Image Pixel.
    auto put_us = [&](uint16_t element, uint16_t value) {
      gdcm::DataElement de(gdcm::Tag(0x0028, element));
      de.SetVR(V::US);
      de.SetByteValue(reinterpret_cast<const char*>(&value), 2);
      ds.Replace(de);
    };
    put_us(0x0002, 1);  // Samples per Pixel
    put(ds, 0x0028, 0x0004, V::CS, "MONOCHROME2");
    put_us(0x0010, static_cast<uint16_t>(rows));
    put_us(0x0011, static_cast<uint16_t>(columns));
    put(ds, 0x0028, 0x0030, V::DS, ds_number(g.spacing_mm[1]) + "\\" + ds_number(g.spacing_mm[0]));
    put_us(0x0100, 16);                     // Bits Allocated
    put_us(0x0101, 12);                     // Bits Stored
    put_us(0x0102, 11);                     // High Bit
    put_us(0x0103, 0);                      // Pixel Representation: unsigned
    put(ds, 0x0028, 0x1050, V::DS, "40");   // Window Center (soft tissue)
    put(ds, 0x0028, 0x1051, V::DS, "400");  // Window Width
    put(ds, 0x0028, 0x1052, V::DS, std::to_string(kIntercept));
    put(ds, 0x0028, 0x1053, V::DS, "1");
    put(ds, 0x0028, 0x1054, V::LO, "HU");
    gdcm::DataElement pixel_data(gdcm::Tag(0x7fe0, 0x0010));
    pixel_data.SetVR(V::OW);
    pixel_data.SetByteValue(reinterpret_cast<const char*>(pixels.data()),
                            static_cast<uint32_t>(per_slice * 2));
    ds.Replace(pixel_data);

    gdcm::FileMetaInformation& meta = writer.GetFile().GetHeader();
    meta.SetDataSetTransferSyntax(gdcm::TransferSyntax::ExplicitVRLittleEndian);
    meta.SetSourceApplicationEntityTitle("ORGANFIT");
    const fs::path file = temp.path() / slice.file.filename();
    detail::write_dicom_file(writer, file, folder / file.filename(),
                             fmt::format("{}: cannot write {}", where, file.filename().string()));
    slices.push_back(std::move(slice));
  }
  temp.commit();
  ct.slices = std::move(slices);
  return clipped;
}

}  // namespace organfit::dicom
