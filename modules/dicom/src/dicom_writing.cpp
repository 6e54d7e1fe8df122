#include "dicom_writing.h"

#include <fmt/format.h>
#include <gdcmFileExplicitFilter.h>
#include <gdcmFileMetaInformation.h>
#include <gdcmSequenceOfItems.h>
#include <gdcmUIDGenerator.h>

#include <ctime>
#include <functional>

#include "dicom_values.h"
#include "organfit/support/atomic_file.h"
#include "organfit/support/error.h"

namespace organfit::dicom::detail {

void put(gdcm::DataSet& ds, std::uint16_t group, std::uint16_t element, const gdcm::VR& vr,
         std::string value) {
  if (value.size() % 2) value.push_back(vr == gdcm::VR::UI ? '\0' : ' ');
  gdcm::DataElement de(gdcm::Tag(group, element));
  de.SetVR(vr);
  de.SetByteValue(value.data(), static_cast<uint32_t>(value.size()));
  ds.Replace(de);
}

void put_derived_object_header(gdcm::DataSet& ds, const PatientStudy& patient,
                               const std::string& date, const std::string& time) {
  using V = gdcm::VR;
  put(ds, 0x0008, 0x0005, V::CS,
      patient.specific_character_set.empty() ? "ISO_IR 192" : patient.specific_character_set);
  put(ds, 0x0008, 0x0012, V::DA, date);
  put(ds, 0x0008, 0x0013, V::TM, time);
  put_patient_study(ds, patient);  // Patient, General Study: verbatim
}

void put_patient_study(gdcm::DataSet& ds, const PatientStudy& p) {
  using V = gdcm::VR;
  put(ds, 0x0008, 0x0020, V::DA, p.study_date);
  put(ds, 0x0008, 0x0030, V::TM, p.study_time);
  put(ds, 0x0008, 0x0050, V::SH, p.accession_number);
  put(ds, 0x0008, 0x0090, V::PN, p.referring_physician_name);
  put(ds, 0x0008, 0x1030, V::LO, p.study_description);
  put(ds, 0x0010, 0x0010, V::PN, p.patient_name);
  put(ds, 0x0010, 0x0020, V::LO, p.patient_id);
  put(ds, 0x0010, 0x0030, V::DA, p.patient_birth_date);
  put(ds, 0x0010, 0x0040, V::CS, p.patient_sex);
  put(ds, 0x0020, 0x000d, V::UI, p.study_instance_uid);
  put(ds, 0x0020, 0x0010, V::SH, p.study_id);
  if (p.other_attributes)
    for (auto at = p.other_attributes->elements.Begin(); at != p.other_attributes->elements.End();
         ++at)
      ds.Replace(*at);
}

bool is_copied_patient_or_study_tag(const gdcm::Tag& t) {
  const std::uint16_t g = t.GetGroup(), e = t.GetElement();
  if (t.IsPrivate() || t.IsGroupLength()) return false;
  switch (g) {
    case 0x0010:  // Patient, Patient Study (age, size, weight, ...)
      return e != 0x0010 && e != 0x0020 && e != 0x0030 && e != 0x0040;
    case 0x0012:  // Clinical Trial Subject, Patient Identity Removed, De-identification
      return e < 0x0050 || (e >= 0x0062 && e <= 0x0064) || e == 0x0081 || e == 0x0082;
    case 0x0008:  // General Study, Patient Study, beyond the named ones
      return e == 0x0051 || e == 0x0096 || e == 0x1032 || e == 0x1048 || e == 0x1049 ||
             e == 0x1060 || e == 0x1062 || e == 0x1080 || e == 0x1084 || e == 0x1110;
    case 0x0032:  // General Study: requesting, requested procedure
      return e == 0x1033 || e == 0x1034 || e == 0x1060 || e == 0x1064 || e == 0x1066 || e == 0x1067;
    case 0x0038:  // Patient Study: admission, service episode
      return e == 0x0010 || e == 0x0014 || e == 0x0060 || e == 0x0062 || e == 0x0064 || e == 0x0500;
    default:
      return false;
  }
}

gdcm::Item new_item() {
  gdcm::Item item;
  item.SetVLToUndefined();
  return item;
}

void put_sequence(gdcm::DataSet& ds, std::uint16_t group, std::uint16_t element,
                  const std::vector<gdcm::Item>& items) {
  gdcm::SmartPointer<gdcm::SequenceOfItems> sq = new gdcm::SequenceOfItems();
  sq->SetLengthToUndefined();
  for (const auto& item : items)
    sq->AddItem(item);
  gdcm::DataElement de(gdcm::Tag(group, element));
  de.SetVR(gdcm::VR::SQ);
  de.SetValue(*sq);
  de.SetVLToUndefined();
  ds.Replace(de);
}

gdcm::Item slice_reference(const CtSlice& slice) {
  gdcm::Item item = new_item();
  put(item.GetNestedDataSet(), 0x0008, 0x1150, gdcm::VR::UI,
      slice.sop_class_uid.empty() ? kCtImageStorage : slice.sop_class_uid);
  put(item.GetNestedDataSet(), 0x0008, 0x1155, gdcm::VR::UI, slice.sop_instance_uid);
  return item;
}

void write_dicom_file(gdcm::Writer& writer, const std::filesystem::path& path,
                      const std::filesystem::path& final_path, const std::string& failed) {
  // GDCM asserts (aborts) on a stream that failed mid-element: it writes to a stream that
  // never fails, judged when closed.
  CheckedFileStream out(path, final_path);
  writer.SetStream(out);
  const bool written = writer.Write();
  out.close();
  if (!written) throw InputError(failed);
}

void write_explicit_vr(gdcm::Writer& writer, const std::filesystem::path& file,
                       const std::string& what) {
  const std::string failed = file.string() + ": cannot write the " + what;
  gdcm::FileMetaInformation& meta = writer.GetFile().GetHeader();
  meta.SetDataSetTransferSyntax(gdcm::TransferSyntax::ExplicitVRLittleEndian);
  meta.SetSourceApplicationEntityTitle("ORGANFIT");
  gdcm::FileExplicitFilter explicit_vr;
  explicit_vr.SetFile(writer.GetFile());
  explicit_vr.SetChangePrivateTags(false);
  if (!explicit_vr.Change()) throw InputError(failed);
  TempPath temp(file);
  write_dicom_file(writer, temp.path(), file, failed);
  temp.commit();
}

std::string ds_number(double v) {
  if (v == 0) v = 0;  // no "-0"
  std::string s = fmt::format("{:.6g}", v);
  if (s.size() > 16) s = fmt::format("{:.8e}", v).substr(0, 16);
  return s;
}

namespace {
std::string local_time(const char* format) {
  const std::time_t now = std::time(nullptr);
  std::tm parts{};
  localtime_r(&now, &parts);
  char text[32];
  std::strftime(text, sizeof text, format, &parts);
  return text;
}
}  // namespace

std::string today_da(bool fixed) {
  return fixed ? "20000101" : local_time("%Y%m%d");
}
std::string now_tm(bool fixed) {
  return fixed ? "000000" : local_time("%H%M%S");
}

std::string make_uid(bool fixed, const std::string& key) {
  if (!fixed) {
    gdcm::UIDGenerator generator;
    return generator.Generate();
  }
  const size_t h = std::hash<std::string>{}(key);
  return fmt::format("1.2.826.0.1.3680043.2.1125.{}", h % 100000000000000ULL);
}

}  // namespace organfit::dicom::detail
