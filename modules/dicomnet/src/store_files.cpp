#include "organfit/dicomnet/store_files.h"

#include <dcmtk/config/osconfig.h>
#include <dcmtk/dcmdata/dcdeftag.h>
#include <dcmtk/dcmdata/dcfilefo.h>
#include <dcmtk/dcmdata/dcmetinf.h>
#include <fmt/format.h>

#include <set>
#include <utility>

#include "association.h"
#include "organfit/support/resources.h"

namespace fs = std::filesystem;

namespace organfit::dicomnet {

StoredFiles store_files(const Node& node, const NetworkOptions& options,
                        const std::vector<fs::path>& files) {
  const Stopwatch clock;
  // Each file's SOP class and transfer syntax, from its meta header (large values are
  // left on disk: DcmSCU reads the file again to send it).
  struct Object {
    fs::path file;
    std::string sop_class, transfer_syntax;
  };
  std::vector<Object> objects;
  std::set<std::pair<std::string, std::string>> contexts;
  for (const fs::path& file : files) {
    DcmFileFormat format;
    OFString sop_class, ts;
    if (format.loadFile(file.c_str(), EXS_Unknown, EGL_noChange, 4096).bad() ||
        format.getMetaInfo()->findAndGetOFString(DCM_MediaStorageSOPClassUID, sop_class).bad() ||
        format.getMetaInfo()->findAndGetOFString(DCM_TransferSyntaxUID, ts).bad() ||
        sop_class.empty() || ts.empty())
      throw InputError(file.string() + ": not a DICOM file with a meta header (cannot be sent)");
    objects.push_back({file, sop_class.c_str(), ts.c_str()});
    contexts.insert({objects.back().sop_class, objects.back().transfer_syntax});
  }
  StoredFiles result;
  if (objects.empty()) return result;

  detail::Association a(node, options);
  std::set<std::string> classes;
  for (const auto& [sop_class, ts] : contexts) {
    a.propose(sop_class, {ts});
    classes.insert(sop_class);
  }
  for (const auto& sop_class : classes)  // fallback: a node that wants another encoding
    a.propose(sop_class, detail::uncompressed_transfer_syntaxes());
  a.scu().setDatasetConversionMode(OFTrue);
  a.open();
  for (const Object& o : objects) {
    T_ASC_PresentationContextID id =
        a.scu().findPresentationContextID(o.sop_class.c_str(), o.transfer_syntax.c_str());
    if (id == 0)
      id = a.context(o.sop_class, fmt::format("C-STORE of {}'s SOP class {}",
                                              o.file.filename().string(), o.sop_class));
    Uint16 status = 0;
    a.check(a.scu().sendSTORERequest(id, OFFilename(o.file.c_str()), nullptr, status),
            "C-STORE of " + o.file.filename().string());
    if (!detail::status_done(status))
      a.fail(fmt::format("refused {}: status {}", o.file.filename().string(),
                         detail::status_text(status)));
    ++result.sent;
    if (status != 0) ++result.warnings;
  }
  result.wall_s = clock.elapsed_s();
  return result;
}

}  // namespace organfit::dicomnet
