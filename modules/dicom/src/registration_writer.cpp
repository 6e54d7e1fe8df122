#include "organfit/dicom/registration_writer.h"

#include <fmt/format.h>
#include <gdcmAttribute.h>
#include <gdcmWriter.h>

#include <Eigen/Geometry>
#include <stdexcept>

#include "dicom_writing.h"
#include "organfit/support/error.h"

namespace fs = std::filesystem;

namespace organfit::dicom {
namespace {
constexpr const char* kDeformableRegistrationClass = "1.2.840.10008.5.1.4.1.1.66.3";
using detail::ds_number;
using detail::new_item;
using detail::put;
using detail::put_sequence;
}  // namespace

void write_deformable_registration(const fs::path& file, const CtSeries& ct,
                                   const geometry::ImageGeometry& grid,
                                   std::vector<float> vectors_mm,
                                   const RegistrationWriteOptions& options) {
  const std::string where = file.string();
  const long long points = grid.voxel_count();
  if (points <= 0 || vectors_mm.size() != static_cast<size_t>(3 * points))
    throw std::invalid_argument("registration: the vectors do not fill the grid");
  if (points > kMostRegistrationGridPoints)
    throw std::invalid_argument("registration: the grid is too large for Vector Grid Data");
  const Eigen::Matrix3d& r = grid.direction;
  if (r.col(0).cross(r.col(1)).dot(r.col(2)) < 1 - 1e-6)
    throw std::invalid_argument("registration: the grid's axes are not right-handed and unit");
  const bool fixed = options.fixed_uids_and_dates;
  auto uid = [&](const std::string& what) {
    return detail::make_uid(fixed, ct.series_instance_uid + "|registration|" + what);
  };
  const std::string date = detail::today_da(fixed), time = detail::now_tm(fixed);

  gdcm::Writer writer;
  gdcm::DataSet& ds = writer.GetFile().GetDataSet();
  using V = gdcm::VR;
  detail::put_derived_object_header(ds, ct.patient, date, time);
  put(ds, 0x0008, 0x0016, V::UI, kDeformableRegistrationClass);
  put(ds, 0x0008, 0x0018, V::UI, uid("sop"));
  put(ds, 0x0008, 0x0023, V::DA, date);  // Content Date, Time: when the grid was made
  put(ds, 0x0008, 0x0033, V::TM, time);
  put(ds, 0x0008, 0x0060, V::CS, "REG");
  put(ds, 0x0008, 0x0070, V::LO, "organfit");  // General and Enhanced General Equipment
  put(ds, 0x0008, 0x1090, V::LO, "organfit");
  put(ds, 0x0018, 0x1000, V::LO, "0");
  put(ds, 0x0018, 0x1020, V::LO, "organfit");
  put(ds, 0x0008, 0x103e, V::LO, "organfit fitted deformation");
  put(ds, 0x0020, 0x000e, V::UI, uid("series"));
  put(ds, 0x0020, 0x0011, V::IS, "1");
  put(ds, 0x0020, 0x0060, V::CS, "");   // Laterality (General Series, 2C): not a paired organ
  put(ds, 0x0020, 0x0013, V::IS, "1");  // Content Identification
  put(ds, 0x0070, 0x0080, V::CS, "ORGANFIT_FIT");
  put(ds, 0x0070, 0x0081, V::LO, "organ fitted to today's points");
  put(ds, 0x0070, 0x0084, V::PN, "");
  put(ds, 0x0020, 0x0052, V::UI, ct.frame_of_reference_uid);  // the Registered RCS
  put(ds, 0x0020, 0x1040, V::LO, "");

  gdcm::Item grid_item = new_item();
  gdcm::DataSet& gds = grid_item.GetNestedDataSet();
  put(gds, 0x0020, 0x0032, V::DS,
      fmt::format("{}\\{}\\{}", ds_number(grid.origin_mm.x()), ds_number(grid.origin_mm.y()),
                  ds_number(grid.origin_mm.z())));
  put(gds, 0x0020, 0x0037, V::DS,
      fmt::format("{}\\{}\\{}\\{}\\{}\\{}", ds_number(r(0, 0)), ds_number(r(1, 0)),
                  ds_number(r(2, 0)), ds_number(r(0, 1)), ds_number(r(1, 1)), ds_number(r(2, 1))));
  gdcm::Attribute<0x0064, 0x0007> dimensions;
  const unsigned int size[3] = {static_cast<unsigned>(grid.size[0]),
                                static_cast<unsigned>(grid.size[1]),
                                static_cast<unsigned>(grid.size[2])};
  dimensions.SetValues(size, 3);
  gds.Replace(dimensions.GetAsDataElement());
  gdcm::Attribute<0x0064, 0x0008> resolution;
  const double spacing[3] = {grid.spacing_mm.x(), grid.spacing_mm.y(), grid.spacing_mm.z()};
  resolution.SetValues(spacing, 3);
  gds.Replace(resolution.GetAsDataElement());
  gdcm::DataElement vectors(gdcm::Tag(0x0064, 0x0009));
  vectors.SetVR(V::OF);
  vectors.SetByteValue(reinterpret_cast<const char*>(vectors_mm.data()),
                       static_cast<uint32_t>(vectors_mm.size() * sizeof(float)));
  std::vector<float>().swap(vectors_mm);  // GDCM holds its copy
  gds.Replace(vectors);

  // The planning CT's slices: registered in the item, and listed by the Common Instance
  // Reference.
  std::vector<gdcm::Item> instances;
  for (const auto& slice : ct.slices)
    instances.push_back(detail::slice_reference(slice));
  gdcm::Item registration = new_item();
  gdcm::DataSet& rds = registration.GetNestedDataSet();
  put(rds, 0x0064, 0x0003, V::UI, ct.frame_of_reference_uid);  // the Source RCS
  put_sequence(rds, 0x0008, 0x1140, instances);                // Referenced Image Sequence
  put_sequence(rds, 0x0070, 0x030d, {});                       // Registration Type Code (2)
  put_sequence(rds, 0x0064, 0x0005, {grid_item});
  put_sequence(ds, 0x0064, 0x0002, {registration});

  gdcm::Item series = new_item();
  put(series.GetNestedDataSet(), 0x0020, 0x000e, V::UI, ct.series_instance_uid);
  put_sequence(series.GetNestedDataSet(), 0x0008, 0x114a, instances);
  put_sequence(ds, 0x0008, 0x1115, {series});

  detail::write_explicit_vr(writer, file, "registration");
}

}  // namespace organfit::dicom
