#pragma once
// The organ stage: the organ on the planning CT's grid, imported from an RT Structure
// Set's ROI (organ.source: rtstruct; the file, the phantom's, or one pulled from
// organ.node) or grown from a seed in an HU window (organ.source: seed).
#include <filesystem>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <vector>

#include "organfit/config/scene.h"
#include "organfit/dicom/ct_series.h"
#include "organfit/dicom/structure_set.h"
#include "organfit/geometry/shape.h"
#include "organfit/pipeline/model_file.h"
#include "organfit/pipeline/node_stage.h"
#include "organfit/segmentation/segment.h"

namespace organfit::pipeline {

/// The scene's seed growing settings (organ.seed_mm, hu_low, hu_high, ...).
segmentation::SeedOptions seed_options_from(const config::Scene& scene);

struct OrganStageResult {
  geometry::Shape shape;   ///< a mask shape (label 1 on the CT's grid)
  OrganLook look;          ///< the source ROI's colour and type (an imported organ)
  nlohmann::json summary;  ///< run.json "organ"
  std::vector<std::string> warnings;
  /// organ.node: what was pulled, and where the structure set is read from and where it
  /// is once the run is committed.
  std::optional<PulledSeries> pulled;
  double pull_wall_s = 0, pull_peak_memory_mib = 0;
  std::filesystem::path rtstruct_file, structure_set_home;
};

/// The organ: its ROI's name and number, grown from a seed or imported (from a file, or
/// pulled from a node), and the key an empty organ is blamed on.
struct OrganStageOptions {
  std::string roi;                                ///< organ.roi
  int roi_number = 0;                             ///< organ.roi_number (0: by name)
  std::optional<segmentation::SeedOptions> seed;  ///< organ.source: seed
  std::optional<StructureSetPullOptions> pull;    ///< organ.node
  config::KeyRef roi_key;                         ///< organ.roi
};
OrganStageOptions organ_stage_options_from(const config::Scene& scene);

/// An organ on the CT's last plane along an axis: the CT does not show whether it ends
/// there. `faces`: one {side, voxels} per such face of the grid (run.json organ.at_ct_edge,
/// empty when none); `warning`: what says so, from `stage` (its prefix: "organ", "segment"),
/// naming `roi` when there is one (empty when none).
struct OrganAtCtEdge {
  nlohmann::json faces = nlohmann::json::array();
  std::string warning;
};
OrganAtCtEdge organ_at_ct_edge(const geometry::LabelVolume& mask, const std::string& stage,
                               const std::string& roi);

/// Makes the organ. `rtstruct_file`: the structure set to import from (the scene's or the
/// phantom's; ignored for a seed or a pull), `rtstruct` that file as already read (null:
/// read here); `staging`/`out_dir` as for the ct stage.
/// Fails naming organ.roi when the organ covers no voxel.
OrganStageResult run_organ_stage(const OrganStageOptions& options, const dicom::CtSeries& ct,
                                 const std::filesystem::path& rtstruct_file,
                                 const std::filesystem::path& staging,
                                 const std::filesystem::path& out_dir,
                                 const dicom::StructureSet* rtstruct = nullptr);

}  // namespace organfit::pipeline
