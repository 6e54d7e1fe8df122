#pragma once
// `organfit dicom echo|find|pull|push`: a DICOM node by hand, as a scene's ct.node,
// organ.node and export.send_to use it. Nothing printed names a patient.
#include <filesystem>
#include <string>
#include <vector>

#include "organfit/dicomnet/find_series.h"
#include "organfit/dicomnet/node.h"

namespace organfit::pipeline {

struct DicomCommand {
  std::string node;  ///< AET@host:port
  dicomnet::NetworkOptions network;
  dicomnet::SeriesQuery query;  ///< find and pull
  bool json = false;            ///< find: the series as JSON
  std::filesystem::path out;    ///< pull: the folder; each series lands in OUT/<series UID>/
  std::vector<std::filesystem::path> files;  ///< push: DICOM files, or folders of them
};

/// C-ECHO; prints the round trip.
void run_dicom_echo(const DicomCommand& command);
/// C-FIND; prints the matching series, one per line (or as JSON).
void run_dicom_find(const DicomCommand& command);
/// C-FIND then C-GET of every matching series into command.out (written whole or not at
/// all, like a run's outputs).
void run_dicom_pull(const DicomCommand& command);
/// C-STORE of the files (a folder: the DICOM Part 10 files in it, recursively).
void run_dicom_push(const DicomCommand& command);

}  // namespace organfit::pipeline
