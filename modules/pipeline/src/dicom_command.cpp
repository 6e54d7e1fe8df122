#include "organfit/pipeline/dicom_command.h"

#include <fmt/format.h>

#include <algorithm>
#include <iostream>
#include <nlohmann/json.hpp>

#include "organfit/dicom/part10.h"
#include "organfit/dicomnet/echo.h"
#include "organfit/dicomnet/retrieve_series.h"
#include "organfit/dicomnet/store_files.h"
#include "organfit/support/output_folder.h"

namespace fs = std::filesystem;

namespace organfit::pipeline {
namespace {

dicomnet::Node node_of(const DicomCommand& c) {
  dicomnet::check_ae_title(c.network.calling_aet, "--aet");
  return dicomnet::parse_node(c.node, "NODE");
}

}  // namespace

void run_dicom_echo(const DicomCommand& c) {
  const dicomnet::Node node = node_of(c);
  const double s = dicomnet::echo(node, c.network);
  std::cout << fmt::format("{}: answered C-ECHO ({:.3f} s)\n", node.text(), s);
}

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

}  // namespace organfit::pipeline
