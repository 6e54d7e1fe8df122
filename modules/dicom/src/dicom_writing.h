#pragma once
// Building DICOM data sets with GDCM, for this module's writers only.
#include <gdcmDataSet.h>
#include <gdcmItem.h>
#include <gdcmVR.h>
#include <gdcmWriter.h>

#include <cstdint>
#include <filesystem>
#include <string>
#include <vector>

#include "organfit/dicom/ct_series.h"

namespace organfit::dicom {
/// See ct_series.h: the source's other Patient and Study attributes, as GDCM read them.
struct CopiedModules {
  gdcm::DataSet elements;
};
}  // namespace organfit::dicom

namespace organfit::dicom::detail {

/// Whether the tag belongs to the Patient, Patient Study, Clinical Trial Subject or
/// General Study modules (the Patient and Study IEs an exported object shares with its
/// CT), other than the attributes PatientStudy holds by name.
bool is_copied_patient_or_study_tag(const gdcm::Tag& tag);

/// Inserts (or replaces) a string element, padded to even length (UIDs with NUL, other
/// VRs with a space). The value is written as given: callers copy source attributes
/// verbatim (see rtstruct_writer.cpp for why).
void put(gdcm::DataSet& ds, std::uint16_t group, std::uint16_t element, const gdcm::VR& vr,
         std::string value);

/// The Patient and General Study attributes of `patient`, copied verbatim (an object
/// must agree with its study: see rtstruct_writer.cpp). Shared by the CT and RTSTRUCT writers.
void put_patient_study(gdcm::DataSet& ds, const PatientStudy& patient);

/// The header an object organfit derives from a CT carries: the specific character set
/// (the CT's, else UTF-8), the instance's creation date and time, and put_patient_study.
/// Shared by the RTSTRUCT and registration writers.
void put_derived_object_header(gdcm::DataSet& ds, const PatientStudy& patient,
                               const std::string& date, const std::string& time);

/// An item of undefined length, ready for a nested data set.
gdcm::Item new_item();

/// Inserts a sequence (undefined length) of `items`.
void put_sequence(gdcm::DataSet& ds, std::uint16_t group, std::uint16_t element,
                  const std::vector<gdcm::Item>& items);

/// An Image SOP Instance Reference item (Referenced SOP Class and Instance UIDs) of a CT
/// slice; a slice read without a SOP Class UID is referenced as a CT Image.
gdcm::Item slice_reference(const CtSlice& slice);

/// Writes the writer's file to `path` (a temporary name of `final_path`) through a stream
/// that never fails under GDCM (it asserts on one that does); throws InputError
/// "FINAL: cannot write: REASON" when a write failed, `failed` when GDCM refused.
void write_dicom_file(gdcm::Writer& writer, const std::filesystem::path& path,
                      const std::filesystem::path& final_path, const std::string& failed);

/// Writes the data set as Explicit VR Little Endian (source AE ORGANFIT) under a temporary
/// name, renamed when whole. Attributes copied from an implicit-VR CT (a sequence's nested
/// elements) get their VRs from the dictionary, as explicit VR needs. Throws InputError
/// "FILE: cannot write the WHAT".
void write_explicit_vr(gdcm::Writer& writer, const std::filesystem::path& file,
                       const std::string& what);

/// A Decimal String value: at most 16 characters.
std::string ds_number(double v);

/// Today's date (DA) and time (TM), local time; or 20000101 / 000000 when `fixed`.
std::string today_da(bool fixed);
std::string now_tm(bool fixed);

/// A new UID under GDCM's root; or, when `fixed`, one derived from `key` (tests and
/// deterministic phantoms: same key, same UID).
std::string make_uid(bool fixed, const std::string& key);

}  // namespace organfit::dicom::detail
