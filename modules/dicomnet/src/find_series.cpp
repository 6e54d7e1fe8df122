#include "organfit/dicomnet/find_series.h"

#include <dcmtk/config/osconfig.h>
#include <dcmtk/dcmdata/dcdeftag.h>
#include <dcmtk/dcmdata/dcuid.h>
#include <fmt/format.h>

#include <algorithm>
#include <memory>
#include <tuple>

#include "association.h"

namespace organfit::dicomnet {
namespace {

std::string text_of(DcmItem& item, const DcmTagKey& tag) {
  OFString value;
  if (item.findAndGetOFString(tag, value).bad()) return {};
  return std::string(value.c_str());
}

int integer_of(DcmItem& item, const DcmTagKey& tag, int absent) {
  const std::string t = text_of(item, tag);
  try {
    return t.empty() ? absent : std::stoi(t);
  } catch (const std::exception&) {
    return absent;
  }
}

/// One C-FIND: the identifiers the node answered with. NodeError on a failure status.
std::vector<std::unique_ptr<DcmDataset>> c_find(detail::Association& a, DcmDataset& query,
                                                const char* level) {
  OFList<QRResponse*> responses;
  const T_ASC_PresentationContextID id =
      a.context(UID_FINDStudyRootQueryRetrieveInformationModel, "C-FIND (Study Root)");
  const OFCondition cond = a.scu().sendFINDRequest(id, &query, &responses);
  std::vector<std::unique_ptr<DcmDataset>> found;
  Uint16 final_status = 0;
  for (QRResponse* r : responses) {
    if (r->m_dataset && (r->m_status == 0xFF00 || r->m_status == 0xFF01)) {
      found.emplace_back(r->m_dataset);
      r->m_dataset = nullptr;
    }
    if (r->m_status != 0xFF00 && r->m_status != 0xFF01) final_status = r->m_status;
    delete r;
  }
  a.check(cond, fmt::format("C-FIND at the {} level", level));
  if (final_status != 0)
    a.fail(fmt::format("answered the {}-level C-FIND with status {}", level,
                       detail::status_text(final_status)));
  return found;
}

}  // namespace

std::string SeriesEntry::text() const {
  std::string t = series_uid + " (" + modality;
  if (!series_description.empty()) t += " '" + organfit::echo(series_description, 40) + "'";
  if (!study_date.empty()) t += ", " + study_date;
  if (instances >= 0) t += fmt::format(", {} {}", instances, instances == 1 ? "object" : "objects");
  return t + ")";
}

std::vector<SeriesEntry> find_series(const Node& node, const NetworkOptions& options,
                                     const SeriesQuery& query) {
  if (query.patient_id.empty() && query.study_uid.empty())
    throw InputError("a C-FIND needs a patient ID or a Study Instance UID");
  detail::Association a(node, options);
  a.propose(UID_FINDStudyRootQueryRetrieveInformationModel,
            detail::uncompressed_transfer_syntaxes());
  a.open();

  // The studies: the one named, or the patient's.
  struct Study {
    std::string uid, date;
  };
  std::vector<Study> studies;
  {
    DcmDataset q;
    q.putAndInsertOFStringArray(DCM_QueryRetrieveLevel, "STUDY");
    q.putAndInsertOFStringArray(DCM_PatientID, query.patient_id.c_str());
    q.putAndInsertOFStringArray(DCM_StudyInstanceUID, query.study_uid.c_str());
    q.putAndInsertOFStringArray(DCM_StudyDate, "");
    for (auto& d : c_find(a, q, "STUDY"))
      if (const std::string uid = text_of(*d, DCM_StudyInstanceUID); !uid.empty())
        studies.push_back({uid, text_of(*d, DCM_StudyDate)});
  }
  std::vector<SeriesEntry> series;
  for (const Study& study : studies) {
    DcmDataset q;
    q.putAndInsertOFStringArray(DCM_QueryRetrieveLevel, "SERIES");
    q.putAndInsertOFStringArray(DCM_StudyInstanceUID, study.uid.c_str());
    q.putAndInsertOFStringArray(DCM_SeriesInstanceUID, query.series_uid.c_str());
    q.putAndInsertOFStringArray(DCM_Modality, query.modality.c_str());
    q.putAndInsertOFStringArray(DCM_SeriesDescription, "");
    q.putAndInsertOFStringArray(DCM_SeriesNumber, "");
    q.putAndInsertOFStringArray(DCM_NumberOfSeriesRelatedInstances, "");
    for (auto& d : c_find(a, q, "SERIES")) {
      SeriesEntry e;
      e.study_uid = study.uid;
      e.study_date = study.date;
      e.series_uid = text_of(*d, DCM_SeriesInstanceUID);
      e.modality = text_of(*d, DCM_Modality);
      e.series_description = text_of(*d, DCM_SeriesDescription);
      e.series_number = integer_of(*d, DCM_SeriesNumber, 0);
      e.instances = integer_of(*d, DCM_NumberOfSeriesRelatedInstances, -1);
      // A node may match more loosely than asked (wildcards, case): keep exact matches.
      if (e.series_uid.empty() || (!query.series_uid.empty() && e.series_uid != query.series_uid) ||
          (!query.modality.empty() && e.modality != query.modality))
        continue;
      series.push_back(std::move(e));
    }
  }
  std::sort(series.begin(), series.end(), [](const SeriesEntry& x, const SeriesEntry& y) {
    return std::tie(x.study_date, x.study_uid, x.series_number, x.series_uid) <
           std::tie(y.study_date, y.study_uid, y.series_number, y.series_uid);
  });
  return series;
}

SeriesEntry choose_series(const std::vector<SeriesEntry>& found, const SeriesQuery& query,
                          const std::string& what, const std::string& series_key) {
  const std::string kind = query.modality.empty() ? "" : query.modality + " ";
  const std::string scope = !query.series_uid.empty()  ? "series " + query.series_uid
                            : !query.study_uid.empty() ? "study " + query.study_uid
                                                       : "this patient ID";
  if (found.empty()) throw InputError(fmt::format("{}: no {}series for {}", what, kind, scope));
  if (found.size() == 1) return found.front();
  std::string list;
  for (const auto& s : found)
    list += (list.empty() ? "" : "; ") + s.text();
  throw InputError(fmt::format("{}: {} {}series for {}: name one with {}: {}", what, found.size(),
                               kind, scope, series_key, list));
}

}  // namespace organfit::dicomnet
