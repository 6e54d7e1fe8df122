#pragma once
// A scene's DICOM nodes: the planning CT and its structure set pulled from a node
// (ct.node, organ.node) into the output folder's cache, and the exported objects sent
// to one (export.send_to). The network itself is dicomnet's; this turns scene keys into
// its calls and its failures into errors naming the scene's key.
#include <filesystem>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "organfit/config/scene.h"
#include "organfit/dicomnet/find_series.h"
#include "organfit/dicomnet/node.h"

namespace organfit::pipeline {

/// The scene's network section, or the defaults when the scene has none.
dicomnet::NetworkOptions network_options(const config::Scene& scene);

/// What a pull fetched, for run.json.
struct PulledSeries {
  std::string study_uid, series_uid;
  std::vector<std::filesystem::path> files;
  double find_s = 0, get_s = 0;  ///< C-FIND and C-GET wall times
  nlohmann::json summary() const;
};

/// What to pull the planning CT from: the node (ct.node), which series (ct.patient_id,
/// ct.study_uid, ct.series_uid), and the keys a failure is named by.
struct CtPullOptions {
  std::string node;  ///< "AET@host:port"
  dicomnet::NetworkOptions network;
  dicomnet::SeriesQuery query;  ///< modality CT
  config::KeyRef node_key;      ///< ct.node: the node failed
  config::KeyRef choice_key;    ///< the most specific key given: no or several series
};
CtPullOptions ct_pull_options_from(const config::Scene& scene);

/// The CT series the options name, retrieved into `folder`. Errors (exit 2) name the
/// scene's key: the node's failure, no CT series there, or several to choose from (listed).
PulledSeries pull_ct(const CtPullOptions& options, const std::filesystem::path& folder);

/// What to pull the structure set from: the node (organ.node), the series (organ.series_uid,
/// or the one holding organ.roi), and the keys a failure is named by.
struct StructureSetPullOptions {
  std::string node;
  dicomnet::NetworkOptions network;
  std::string roi, series_uid;
  config::KeyRef node_key;    ///< organ.node
  config::KeyRef choice_key;  ///< organ.series_uid when given, else organ.node
};
StructureSetPullOptions structure_set_pull_options_from(const config::Scene& scene);

/// The RT Structure Set the options name in study `study_uid` (the CT's), retrieved into
/// `folder`/<series UID>/: the given series, or the study's only RTSTRUCT series, or the
/// only one of several that holds the ROI (several: an error listing them). A structure
/// set series must hold one object.
PulledSeries pull_structure_set(const StructureSetPullOptions& options,
                                const std::string& study_uid, const std::filesystem::path& folder);

/// Where the exported objects go: the node (export.send_to), and the key a failure is
/// named by.
struct SendOptions {
  std::string node;
  dicomnet::NetworkOptions network;
  config::KeyRef node_key;  ///< export.send_to
};
SendOptions send_options_from(const config::Scene& scene);

/// Sends `files` to the node. Returns run.json's record of the send; a failure throws
/// naming export.send_to.
nlohmann::json send_exported(const SendOptions& options,
                             const std::vector<std::filesystem::path>& files);

}  // namespace organfit::pipeline
