#include "organfit/dicomnet/retrieve_series.h"

#include <dcmtk/config/osconfig.h>
#include <dcmtk/dcmdata/dcdeftag.h>
#include <dcmtk/dcmdata/dcfilefo.h>
#include <dcmtk/dcmdata/dcuid.h>
#include <fmt/format.h>

#include <system_error>

#include "association.h"
#include "organfit/support/resources.h"

namespace fs = std::filesystem;

namespace organfit::dicomnet {
namespace {

/// The storage classes a retrieval accepts: the objects organfit reads.
const char* const kStorageClasses[] = {
    UID_CTImageStorage,
    UID_MRImageStorage,
    UID_UltrasoundImageStorage,
    UID_UltrasoundMultiframeImageStorage,
    UID_RTStructureSetStorage,
    UID_SpatialRegistrationStorage,
    UID_DeformableSpatialRegistrationStorage,
};

/// A UID as a file name: digits and dots only, so that no object names a path.
bool is_uid(const std::string& uid) {
  if (uid.empty() || uid.size() > 64 || uid.front() == '.') return false;
  for (const char c : uid)
    if (!(c == '.' || (c >= '0' && c <= '9'))) return false;
  return true;
}

/// Writes each object the node sends during the C-GET to `folder` as <SOP Instance
/// UID>.dcm, through a temporary name (a file is whole or absent).
class RetrievingScu : public DcmSCU {
 public:
  explicit RetrievingScu(fs::path folder) : folder_(std::move(folder)) {}

  OFCondition handleSTORERequest(const T_ASC_PresentationContextID /*presID*/, DcmDataset* incoming,
                                 OFBool& continue_session, Uint16& status) override {
    std::unique_ptr<DcmDataset> dataset(incoming);
    continue_session = OFTrue;
    OFString uid;
    if (!dataset || dataset->findAndGetOFString(DCM_SOPInstanceUID, uid).bad() ||
        !is_uid(uid.c_str())) {
      ++refused;
      status = 0xC000;  // cannot understand
      return EC_Normal;
    }
    const fs::path file = folder_ / (std::string(uid.c_str()) + ".dcm");
    const fs::path temporary = folder_ / ("." + std::string(uid.c_str()) + ".part");
    DcmFileFormat format(dataset.get());  // a copy with a new meta header
    const OFCondition saved =
        format.saveFile(temporary.c_str(), dataset->getOriginalXfer(), EET_ExplicitLength);
    std::error_code ec;
    if (saved.good()) fs::rename(temporary, file, ec);
    if (saved.bad() || ec) {
      fs::remove(temporary, ec);
      ++refused;
      status = 0xA700;  // out of resources: the disk
      write_error = saved.bad() ? saved.text() : ec.message();
      return EC_Normal;
    }
    files.push_back(file);
    status = 0x0000;
    return EC_Normal;
  }

  std::vector<fs::path> files;
  int refused = 0;
  std::string write_error;

 private:
  fs::path folder_;
};

}  // namespace

RetrievedSeries retrieve_series(const Node& node, const NetworkOptions& options,
                                const std::string& study_uid, const std::string& series_uid,
                                const fs::path& folder) {
  const Stopwatch clock;
  std::error_code ec;
  fs::create_directories(folder, ec);
  if (ec || !fs::is_directory(folder))
    throw InputError(folder.string() + ": cannot create the folder to retrieve into");
  auto owned = std::make_unique<RetrievingScu>(folder);
  RetrievingScu& scu = *owned;
  detail::Association a(node, options, std::move(owned));
  a.propose(UID_GETStudyRootQueryRetrieveInformationModel,
            detail::uncompressed_transfer_syntaxes());
  std::vector<std::string> accepted = detail::uncompressed_transfer_syntaxes();
  for (const char* ts : {UID_JPEGProcess14SV1TransferSyntax, UID_JPEGLSLosslessTransferSyntax,
                         UID_JPEG2000LosslessOnlyTransferSyntax, UID_RLELosslessTransferSyntax,
                         UID_DeflatedExplicitVRLittleEndianTransferSyntax})
    accepted.emplace_back(ts);
  for (const char* sop_class : kStorageClasses)
    a.propose(sop_class, accepted, ASC_SC_ROLE_SCP);
  a.open();

  DcmDataset query;
  query.putAndInsertOFStringArray(DCM_QueryRetrieveLevel, "SERIES");
  query.putAndInsertOFStringArray(DCM_StudyInstanceUID, study_uid.c_str());
  query.putAndInsertOFStringArray(DCM_SeriesInstanceUID, series_uid.c_str());
  OFList<RetrieveResponse*> responses;
  const OFCondition cond = a.scu().sendCGETRequest(
      a.context(UID_GETStudyRootQueryRetrieveInformationModel, "C-GET (Study Root)"), &query,
      &responses);
  Uint16 final_status = 0;
  int failed = 0, warned = 0;
  for (RetrieveResponse* r : responses) {
    if (r->m_status != 0xFF00) {
      final_status = r->m_status;
      failed = r->m_numberOfFailedSubops;
      warned = r->m_numberOfWarningSubops;
    }
    delete r;
  }
  a.check(cond, "C-GET");
  const std::string series = fmt::format("series {} of study {}", series_uid, study_uid);
  if (!scu.write_error.empty())
    a.fail(fmt::format("C-GET of {}: cannot write into {}: {}", series, folder.string(),
                       scu.write_error));
  if (scu.refused > 0)
    a.fail(fmt::format("C-GET of {}: {} object(s) without a valid SOP Instance UID", series,
                       scu.refused));
  if (final_status != 0x0000 || failed > 0)
    a.fail(fmt::format("C-GET of {}: status {}, {} sub-operation(s) failed, {} with a warning",
                       series, detail::status_text(final_status), failed, warned));
  if (scu.files.empty()) a.fail(fmt::format("C-GET of {}: the node sent no object", series));
  RetrievedSeries result;
  result.files = std::move(scu.files);
  result.wall_s = clock.elapsed_s();
  return result;
}

}  // namespace organfit::dicomnet
