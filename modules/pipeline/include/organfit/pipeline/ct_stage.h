#pragma once
// The ct stage: the planning CT read as one series (dicom/ct_series.h), from the scene's
// ct.folder, from a DICOM node (ct.node: pulled into the run's cache first) or from the
// phantom the run made.
#include <filesystem>
#include <optional>

#include "organfit/config/scene.h"
#include "organfit/dicom/ct_series.h"
#include "organfit/pipeline/node_stage.h"

namespace organfit::pipeline {

/// The scene's `ct` section as the reader's options (which series of the folder).
dicom::CtReadOptions ct_options_from(const config::Scene& scene);

struct CtStageResult {
  dicom::CtSeries ct;
  std::filesystem::path folder;        ///< where it was read
  std::filesystem::path home;          ///< where that folder is once the run is committed
  std::optional<PulledSeries> pulled;  ///< ct.node: what was pulled
  double pull_wall_s = 0, read_wall_s = 0;
  double pull_peak_memory_mib = 0;  ///< the process's peak once the pull was done
};

/// Where the CT comes from: a folder (ct.folder), a node (ct.node), or, with neither, the
/// phantom the run made; and which series.
struct CtStageOptions {
  dicom::CtReadOptions read;
  std::optional<std::filesystem::path> folder;  ///< ct.folder
  std::optional<CtPullOptions> pull;            ///< ct.node
};
CtStageOptions ct_stage_options_from(const config::Scene& scene);

/// Reads the CT. `staging`/`out_dir`: the run's staging folder and --out (a pulled
/// series goes into staging/cache/ct, at home in out_dir/cache/ct); `phantom_ct`/
/// `phantom_home`: the phantom's CT folder when the options name neither folder nor node.
CtStageResult run_ct_stage(const CtStageOptions& options, const std::filesystem::path& staging,
                           const std::filesystem::path& out_dir,
                           const std::filesystem::path& phantom_ct,
                           const std::filesystem::path& phantom_home);

}  // namespace organfit::pipeline
