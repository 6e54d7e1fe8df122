// `organfit dicom echo|find|pull|push`: a DICOM node by hand, as a scene's ct.node,
// organ.node and export.send_to use it. Nothing printed names a patient.
#include <fmt/format.h>

#include <CLI/CLI.hpp>
#include <algorithm>
#include <filesystem>
#include <iostream>
#include <memory>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "commands.h"
#include "organfit/dicom/part10.h"
#include "organfit/dicomnet/echo.h"
#include "organfit/dicomnet/find_series.h"
#include "organfit/dicomnet/node.h"
#include "organfit/dicomnet/retrieve_series.h"
#include "organfit/dicomnet/store_files.h"
#include "organfit/support/output_folder.h"

namespace fs = std::filesystem;

namespace organfit::app {
namespace {

struct DicomCommand {
  std::string node;  ///< AET@host:port
  dicomnet::NetworkOptions network;
  dicomnet::SeriesQuery query;  ///< find and pull
  bool json = false;            ///< find: the series as JSON
  std::filesystem::path out;    ///< pull: the folder; each series lands in OUT/<series UID>/
  std::vector<std::filesystem::path> files;  ///< push: DICOM files, or folders of them
};

dicomnet::Node node_of(const DicomCommand& c) {
  dicomnet::check_ae_title(c.network.calling_aet, "--aet");
  return dicomnet::parse_node(c.node, "NODE");
}

/// C-ECHO; prints the round trip.
void run_dicom_echo(const DicomCommand& c) {
  const dicomnet::Node node = node_of(c);
  const double s = dicomnet::echo(node, c.network);
  std::cout << fmt::format("{}: answered C-ECHO ({:.3f} s)\n", node.text(), s);
}

/// C-FIND; prints the matching series, one per line (or as JSON).
void run_dicom_find(const DicomCommand& c) {
  const dicomnet::Node node = node_of(c);
  const auto found = dicomnet::find_series(node, c.network, c.query);
  if (c.json) {
    nlohmann::json list = nlohmann::json::array();
    for (const auto& s : found)
      list.push_back({{"study_uid", s.study_uid},
                      {"series_uid", s.series_uid},
                      {"modality", s.modality},
                      {"series_description", s.series_description},
                      {"series_number", s.series_number},
                      {"study_date", s.study_date},
                      {"instances", s.instances}});
    std::cout << list.dump(2) << "\n";
    return;
  }
  std::cout << fmt::format("{:<8} {:<8} {:>6} {:>7}  {:<24} {}\n", "date", "modality", "number",
                           "objects", "description", "study UID / series UID");
  for (const auto& s : found)
    std::cout << fmt::format("{:<8} {:<8} {:>6} {:>7}  {:<24} {} / {}\n", s.study_date, s.modality,
                             s.series_number, s.instances, echo(s.series_description, 24),
                             s.study_uid, s.series_uid);
  std::cout << fmt::format("{} series\n", found.size());
}

/// C-FIND then C-GET of every matching series into command.out (written whole or not at
/// all, like a run's outputs).
void run_dicom_pull(const DicomCommand& c) {
  const dicomnet::Node node = node_of(c);
  const auto found = dicomnet::find_series(node, c.network, c.query);
  if (found.empty()) throw InputError(fmt::format("{}: no series matches the query", node.text()));
  check_output_location(c.out, {}, "--out");
  std::set<std::string> names;
  for (const auto& s : found)
    names.insert(s.series_uid + "/");
  OutputFolder output(c.out, names);
  size_t objects = 0;
  for (const auto& s : found) {
    const auto got = dicomnet::retrieve_series(node, c.network, s.study_uid, s.series_uid,
                                               output.staging() / s.series_uid);
    objects += got.files.size();
    std::cout << fmt::format("{} {} objects in {:.2f} s: {}/\n", s.modality, got.files.size(),
                             got.wall_s, (c.out / s.series_uid).string());
  }
  output.commit();
  std::cout << fmt::format("{} series, {} objects\n", found.size(), objects);
}

/// C-STORE of the files (a folder: the DICOM Part 10 files in it, recursively).
void run_dicom_push(const DicomCommand& c) {
  const dicomnet::Node node = node_of(c);
  std::vector<fs::path> files;
  for (const fs::path& p : c.files) {
    std::error_code ec;
    if (fs::is_directory(p, ec)) {
      std::vector<fs::path> inside;
      for (const auto& e : fs::recursive_directory_iterator(p, ec))
        if (e.is_regular_file() && dicom::is_part10(e.path())) inside.push_back(e.path());
      if (inside.empty()) throw InputError(p.string() + ": the folder holds no DICOM file");
      std::sort(inside.begin(), inside.end());
      files.insert(files.end(), inside.begin(), inside.end());
    } else if (!fs::is_regular_file(p, ec)) {
      throw InputError(p.string() + ": no such file or folder");
    } else {
      files.push_back(p);
    }
  }
  const auto stored = dicomnet::store_files(node, c.network, files);
  std::cout << fmt::format(
      "{}: {} object(s) sent in {:.2f} s{}\n", node.text(), stored.sent, stored.wall_s,
      stored.warnings ? fmt::format(" ({} with a warning status)", stored.warnings) : "");
}

}  // namespace

std::vector<Command> add_dicom(CLI::App& app) {
  auto dcm = std::make_shared<DicomCommand>();
  auto* dicom = app.add_subcommand(
      "dicom",
      "A DICOM node by hand (echo, find, pull, push), as ct.node and export.send_to use it");
  dicom->require_subcommand(1);
  auto add_node = [dcm](CLI::App* command) {
    command->add_option("node", dcm->node, "The node: AET@host:port")->required();
    command->add_option("--aet", dcm->network.calling_aet, "Our own AE title");
    command->add_option("--timeout", dcm->network.timeout_s, "Seconds before a silent node fails")
        ->check(CLI::Range(0.1, 600.0));
  };
  auto add_query = [dcm](CLI::App* command) {
    command->add_option("--patient-id", dcm->query.patient_id, "Patient ID (never printed)");
    command->add_option("--study", dcm->query.study_uid, "Study Instance UID");
    command->add_option("--series", dcm->query.series_uid, "Series Instance UID");
    command->add_option("--modality", dcm->query.modality,
                        "Only series of this modality (CT, RTSTRUCT, ...)");
  };
  auto* dicom_echo = dicom->add_subcommand("echo", "C-ECHO: does the node answer");
  add_node(dicom_echo);
  auto* dicom_find =
      dicom->add_subcommand("find", "C-FIND: the series of a patient or a study (no names)");
  add_node(dicom_find);
  add_query(dicom_find);
  dicom_find->add_flag("--json", dcm->json, "As JSON");
  auto* dicom_pull = dicom->add_subcommand(
      "pull", "C-FIND, then C-GET of each matching series into OUT/<series UID>/");
  add_node(dicom_pull);
  add_query(dicom_pull);
  dicom_pull->add_option("-o,--out", dcm->out, "Output folder (created)")->required();
  auto* dicom_push = dicom->add_subcommand("push", "C-STORE of DICOM files (or folders of them)");
  add_node(dicom_push);
  dicom_push->add_option("files", dcm->files, "Files or folders")->required();
  return {{dicom_echo, [dcm] { return run_dicom_echo(*dcm), 0; }},
          {dicom_find, [dcm] { return run_dicom_find(*dcm), 0; }},
          {dicom_pull, [dcm] { return run_dicom_pull(*dcm), 0; }},
          {dicom_push, [dcm] { return run_dicom_push(*dcm), 0; }}};
}

}  // namespace organfit::app
