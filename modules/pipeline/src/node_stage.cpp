#include "organfit/pipeline/node_stage.h"

#include <fmt/format.h>

#include <functional>

#include "organfit/dicom/structure_set.h"
#include "organfit/dicomnet/find_series.h"
#include "organfit/dicomnet/retrieve_series.h"
#include "organfit/dicomnet/store_files.h"
#include "organfit/support/resources.h"

namespace fs = std::filesystem;

namespace organfit::pipeline {
namespace {

/// Runs a network call; a node's failure becomes an error naming the scene's key.
template <typename F>
auto naming_key(const config::KeyRef& key, F&& call) {
  try {
    return call();
  } catch (const Error& e) {  // a node's failure, or its answer not usable
    key.fail(e.what());
  }
}

}  // namespace

dicomnet::NetworkOptions network_options(const config::Scene& scene) {
  dicomnet::NetworkOptions o;  // the schema's defaults are these
  if (scene.has_section("network")) {
    o.calling_aet = scene.text("network", "aet");
    o.timeout_s = scene.number("network", "timeout_s");
  }
  return o;
}

nlohmann::json PulledSeries::summary() const {
  return {{"study_uid", study_uid},
          {"series_uid", series_uid},
          {"objects", files.size()},
          {"find_s", find_s},
          {"get_s", get_s}};
}

CtPullOptions ct_pull_options_from(const config::Scene& scene) {
  CtPullOptions o;
  o.node = scene.text("ct", "node");
  o.network = network_options(scene);
  o.query.patient_id = scene.text("ct", "patient_id");
  o.query.study_uid = scene.text("ct", "study_uid");
  o.query.series_uid = scene.text("ct", "series_uid");
  o.query.modality = "CT";
  o.node_key = scene.key("ct", "node");
  o.choice_key = scene.key("ct", scene.is_given("ct", "series_uid")  ? "series_uid"
                                 : scene.is_given("ct", "study_uid") ? "study_uid"
                                                                     : "patient_id");
  return o;
}

PulledSeries pull_ct(const CtPullOptions& o, const fs::path& folder) {
  const dicomnet::Node node = dicomnet::parse_node(o.node, "ct.node");
  const dicomnet::NetworkOptions& options = o.network;
  const dicomnet::SeriesQuery& query = o.query;
  PulledSeries pulled;
  Stopwatch clock;
  const auto found =
      naming_key(o.node_key, [&] { return dicomnet::find_series(node, options, query); });
  const dicomnet::SeriesEntry series = naming_key(o.choice_key, [&] {
    return dicomnet::choose_series(found, query, node.text() + " holds", "ct.series_uid");
  });
  pulled.find_s = clock.elapsed_s();
  clock.restart();
  pulled.study_uid = series.study_uid;
  pulled.series_uid = series.series_uid;
  pulled.files = naming_key(o.node_key, [&] {
    return dicomnet::retrieve_series(node, options, series.study_uid, series.series_uid, folder)
        .files;
  });
  pulled.get_s = clock.elapsed_s();
  return pulled;
}

StructureSetPullOptions structure_set_pull_options_from(const config::Scene& scene) {
  StructureSetPullOptions o;
  o.node = scene.text("organ", "node");
  o.network = network_options(scene);
  o.roi = scene.text("organ", "roi");
  o.series_uid = scene.text("organ", "series_uid");
  o.node_key = scene.key("organ", "node");
  o.choice_key = scene.key("organ", scene.is_given("organ", "series_uid") ? "series_uid" : "node");
  return o;
}

PulledSeries pull_structure_set(const StructureSetPullOptions& o, const std::string& study_uid,
                                const fs::path& folder) {
  const dicomnet::Node node = dicomnet::parse_node(o.node, "organ.node");
  const dicomnet::NetworkOptions& options = o.network;
  const std::string& roi = o.roi;
  dicomnet::SeriesQuery query;
  query.study_uid = study_uid;
  query.series_uid = o.series_uid;
  query.modality = "RTSTRUCT";
  PulledSeries pulled;
  Stopwatch clock;
  std::vector<dicomnet::SeriesEntry> found =
      naming_key(o.node_key, [&] { return dicomnet::find_series(node, options, query); });
  pulled.find_s = clock.elapsed_s();
  clock.restart();
  // Each candidate series, retrieved: a structure set is one small object.
  auto retrieve = [&](const dicomnet::SeriesEntry& s) {
    auto files = naming_key(o.node_key, [&] {
      return dicomnet::retrieve_series(node, options, s.study_uid, s.series_uid,
                                       folder / s.series_uid)
          .files;
    });
    if (files.size() != 1)
      o.node_key.fail(fmt::format("{}: the structure set series {} holds {} objects, not one",
                                  node.text(), s.series_uid, files.size()));
    return files.front();
  };
  // Several structure sets in the study (an earlier fit sent back, a colleague's): the
  // ones holding the organ's ROI are the candidates.
  if (found.size() > 1 && query.series_uid.empty()) {
    std::vector<dicomnet::SeriesEntry> holding;
    std::vector<fs::path> files;
    for (const auto& s : found) {
      fs::path file = retrieve(s);
      if (!dicom::read_rtstruct(file).rois_named(roi).empty()) {
        holding.push_back(s);
        files.push_back(std::move(file));
      }
    }
    if (holding.size() == 1) {
      pulled.study_uid = holding.front().study_uid;
      pulled.series_uid = holding.front().series_uid;
      pulled.files = {files.front()};
      pulled.get_s = clock.elapsed_s();
      return pulled;
    }
    if (!holding.empty()) found = holding;
    query.modality = holding.empty() ? "RTSTRUCT" : "RTSTRUCT (with ROI '" + echo(roi) + "')";
  }
  const dicomnet::SeriesEntry series = naming_key(o.choice_key, [&] {
    return dicomnet::choose_series(found, query, node.text() + " holds (in the CT's study)",
                                   "organ.series_uid");
  });
  pulled.study_uid = series.study_uid;
  pulled.series_uid = series.series_uid;
  pulled.files = {retrieve(series)};
  pulled.get_s = clock.elapsed_s();
  return pulled;
}

SendOptions send_options_from(const config::Scene& scene) {
  SendOptions o;
  o.node = scene.text("export", "send_to");
  o.network = network_options(scene);
  o.node_key = scene.key("export", "send_to");
  return o;
}

nlohmann::json send_exported(const SendOptions& o, const std::vector<fs::path>& files) {
  const dicomnet::Node node = dicomnet::parse_node(o.node, "export.send_to");
  const dicomnet::StoredFiles stored =
      naming_key(o.node_key, [&] { return dicomnet::store_files(node, o.network, files); });
  nlohmann::json names = nlohmann::json::array();
  for (const auto& f : files)
    names.push_back(f.filename().string());
  return {{"node", node.text()},
          {"files", names},
          {"sent", stored.sent},
          {"with_warning_status", stored.warnings},
          {"wall_s", stored.wall_s}};
}

}  // namespace organfit::pipeline
