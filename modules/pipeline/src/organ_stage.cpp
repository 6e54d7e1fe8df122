#include "organfit/pipeline/organ_stage.h"

#include <fmt/format.h>
#include <spdlog/spdlog.h>

#include <array>

#include "organfit/dicom/structure_set.h"
#include "organfit/geometry/grid_edges.h"
#include "organfit/pipeline/scene_schema.h"
#include "organfit/support/error.h"
#include "organfit/support/resources.h"

namespace fs = std::filesystem;

namespace organfit::pipeline {

segmentation::SeedOptions seed_options_from(const config::Scene& scene) {
  return keys::organ_seed().read(scene);
}

OrganStageOptions organ_stage_options_from(const config::Scene& scene) {
  OrganStageOptions o;
  o.roi = scene.text("organ", "roi");
  o.roi_key = scene.key("organ", "roi");
  if (scene.text("organ", "source") == "seed") {
    o.seed = seed_options_from(scene);
    return o;
  }
  o.roi_number = static_cast<int>(scene.integer("organ", "roi_number"));
  if (scene.is_given("organ", "node")) o.pull = structure_set_pull_options_from(scene);
  return o;
}

OrganAtCtEdge organ_at_ct_edge(const geometry::LabelVolume& mask, const std::string& stage,
                               const std::string& roi) {
  OrganAtCtEdge out;
  const std::array<long long, 6> on_faces = geometry::voxels_on_faces(mask);
  std::string sides;
  for (int face = 0; face < 6; ++face) {
    const long long voxels = on_faces[static_cast<size_t>(face)];
    if (voxels == 0) continue;
    const char* side = geometry::side_of_face(mask.geometry, face);
    out.faces.push_back({{"side", side}, {"voxels", voxels}});
    sides +=
        fmt::format("{}{} ({} voxels on its last plane)", sides.empty() ? "" : ", ", side, voxels);
  }
  if (!sides.empty())
    out.warning = fmt::format(
        "{}: {} reaches the CT's edge: {}. It may go on beyond the CT's field of view; only "
        "the part the CT shows is taken",
        stage, roi.empty() ? std::string("the organ") : "'" + echo(roi) + "'", sides);
  return out;
}

OrganStageResult run_organ_stage(const OrganStageOptions& options, const dicom::CtSeries& ct,
                                 const fs::path& rtstruct_file, const fs::path& staging,
                                 const fs::path& out_dir, const dicom::StructureSet* rtstruct) {
  OrganStageResult r;
  const std::string& roi = options.roi;
  geometry::LabelVolume mask;
  if (options.seed) {
    segmentation::SeededOrgan grown =
        segmentation::segment_from_seed(ct.geometry, ct.hu, *options.seed);
    r.warnings = grown.warnings;
    mask = std::move(grown.mask);
    r.summary = {{"roi", roi}, {"source", "seed"}, {"volume_cm3", mask.volume_mm3(1) / 1000.0}};
    spdlog::info("organ: '{}' grown from the seed, {:.2f} cm3", roi, mask.volume_mm3(1) / 1000.0);
  } else {
    r.rtstruct_file = rtstruct_file;
    if (options.pull) {
      Stopwatch clock;
      r.pulled = pull_structure_set(*options.pull, ct.patient.study_instance_uid,
                                    staging / "cache" / "rtstruct");
      r.rtstruct_file = r.pulled->files.front();
      r.structure_set_home = out_dir / fs::relative(r.rtstruct_file, staging);
      r.pull_wall_s = clock.elapsed_s();
      r.pull_peak_memory_mib = peak_memory_mib();
      spdlog::info("organ: the structure set pulled from {} in {:.2f} s", options.pull->node,
                   r.pull_wall_s);
    }
    const fs::path& file = r.rtstruct_file;
    std::optional<dicom::StructureSet> read;
    if (!rtstruct || options.pull) rtstruct = &read.emplace(dicom::read_rtstruct(file));
    dicom::RasterisedRoi imported =
        dicom::rasterise_roi(*rtstruct, roi, ct, file.string(), options.roi_number);
    r.warnings = imported.warnings;
    r.summary = {{"roi", roi},
                 {"source", "rtstruct"},
                 {"contours", imported.contours},
                 {"matched_by_position", imported.matched_by_position},
                 {"volume_cm3", imported.mask.volume_mm3(1) / 1000.0}};
    spdlog::info("organ: ROI '{}', {} contours, {:.2f} cm3", roi, imported.contours,
                 imported.mask.volume_mm3(1) / 1000.0);
    r.look = {imported.colour, imported.interpreted_type};  // an empty type is written as ORGAN
    mask = std::move(imported.mask);
  }
  if (mask.count(1) == 0)
    options.roi_key.fail("the organ '" + echo(roi) + "' covers no voxel of the CT");
  const OrganAtCtEdge edge = organ_at_ct_edge(mask, "organ", roi);
  r.summary["at_ct_edge"] = edge.faces;
  if (!edge.warning.empty()) r.warnings.push_back(edge.warning);
  r.shape =
      geometry::make_mask_shape(std::make_shared<const geometry::LabelVolume>(std::move(mask)));
  return r;
}

}  // namespace organfit::pipeline
