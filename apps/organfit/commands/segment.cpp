// `organfit segment`: an organ mask from a CT, imported from an RT Structure Set or grown
// from a seed, written with the CT's geometry.
#include "organfit/segmentation/segment.h"

#include <spdlog/spdlog.h>

#include <CLI/CLI.hpp>
#include <Eigen/Core>
#include <filesystem>
#include <iostream>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "commands.h"
#include "organfit/dicom/structure_set.h"
#include "organfit/itkbridge/itk_images.h"
#include "organfit/pipeline/organ_stage.h"
#include "organfit/support/error.h"
#include "organfit/support/output_folder.h"

namespace organfit::app {
namespace {

struct SegmentRequest {
  std::filesystem::path ct_folder;
  std::string series_uid;
  std::filesystem::path rtstruct;  ///< with roi: import
  std::string roi;
  int roi_number = 0;             ///< or by ROI Number (> 0), when names repeat
  std::vector<double> seed_mm;    ///< x,y,z with hu: grow from a seed
  std::vector<double> hu_window;  ///< low,high
  double search_box_mm = 200;     ///< cube around the seed grown in (0: the whole CT)
  std::filesystem::path out;      ///< .nrrd, .mha, .nii(.gz)
};

struct SegmentResult {
  double volume_cm3 = 0;
  std::vector<std::string> warnings;
};

/// Throws InputError on bad input (and writes nothing then).
SegmentResult run_segment(const SegmentRequest& r) {
  const bool import = !r.rtstruct.empty() || !r.roi.empty() || r.roi_number > 0;
  const bool grow = !r.seed_mm.empty() || !r.hu_window.empty();
  if (import == grow)
    throw InputError("segment: give either --rtstruct and --roi, or --seed and --hu");
  if (import && (r.rtstruct.empty() || (r.roi.empty() && r.roi_number <= 0)))
    throw InputError("segment: --rtstruct and --roi (or --roi-number) go together");
  if (grow && (r.seed_mm.size() != 3 || r.hu_window.size() != 2))
    throw InputError("segment: --seed takes X,Y,Z (mm) and --hu takes LOW,HIGH");
  check_output_location(
      r.out.parent_path().empty() ? std::filesystem::path(".") : r.out.parent_path(),
      {r.ct_folder, r.rtstruct}, "--out", OutputKind::kFile);
  dicom::CtReadOptions o;
  o.series_instance_uid = r.series_uid;
  std::optional<dicom::StructureSet> rtss;
  if (import) {  // of several CT series, the one it was drawn on
    rtss = dicom::read_rtstruct(r.rtstruct);
    o.referenced_series_uids = rtss->referenced_series_uids;
  }
  const dicom::CtSeries ct = dicom::read_ct_series(r.ct_folder, o);
  if (!ct.choice.empty()) spdlog::info("ct: {}", ct.choice);
  SegmentResult result;
  result.warnings = ct.warnings;
  geometry::LabelVolume mask;
  if (import) {
    dicom::RasterisedRoi roi =
        dicom::rasterise_roi(*rtss, r.roi, ct, r.rtstruct.string(), r.roi_number);
    result.warnings.insert(result.warnings.end(), roi.warnings.begin(), roi.warnings.end());
    mask = std::move(roi.mask);
  } else {
    segmentation::SeedOptions s;
    s.seed_mm = Eigen::Vector3d(r.seed_mm[0], r.seed_mm[1], r.seed_mm[2]);
    s.hu_low = r.hu_window[0];
    s.hu_high = r.hu_window[1];
    s.search_box_mm = r.search_box_mm;
    segmentation::SeededOrgan organ = segmentation::segment_from_seed(ct.geometry, ct.hu, s);
    result.warnings.insert(result.warnings.end(), organ.warnings.begin(), organ.warnings.end());
    mask = std::move(organ.mask);
  }
  const pipeline::OrganAtCtEdge edge =
      pipeline::organ_at_ct_edge(mask, "segment", import ? r.roi : std::string());
  if (!edge.warning.empty()) result.warnings.push_back(edge.warning);
  result.volume_cm3 = mask.volume_mm3(1) / 1000.0;
  CreatedFolders folders(r.out.parent_path().empty() ? std::filesystem::path(".")
                                                     : r.out.parent_path());
  itkbridge::write_label_volume(r.out, mask);
  folders.keep();
  return result;
}

}  // namespace

Command add_segment(CLI::App& app) {
  auto seg = std::make_shared<SegmentRequest>();
  auto* segment = app.add_subcommand(
      "segment", "An organ mask from a CT: imported from an RTSTRUCT or grown from a seed");
  segment->add_option("--ct", seg->ct_folder, "Folder of the CT series")->required();
  segment->add_option("--series-uid", seg->series_uid,
                      "Series Instance UID when the folder holds several CT series");
  segment->add_option("--rtstruct", seg->rtstruct, "RT Structure Set to import from");
  segment->add_option("--roi", seg->roi, "ROI name in the structure set");
  segment
      ->add_option("--roi-number", seg->roi_number,
                   "ROI Number in the structure set, when several ROIs share the name")
      ->check(CLI::PositiveNumber);
  segment->add_option("--seed", seg->seed_mm, "Seed X,Y,Z in mm (patient LPS)")
      ->delimiter(',')
      ->expected(3);
  segment->add_option("--hu", seg->hu_window, "HU window LOW,HIGH")->delimiter(',')->expected(2);
  segment
      ->add_option("--search-box", seg->search_box_mm,
                   "Side (mm) of the cube around the seed grown in; 0 = whole CT")
      ->check(CLI::Range(0.0, 2000.0));
  segment->add_option("-o,--out", seg->out, "Mask file (.nrrd, .mha, .nii, .nii.gz)")->required();
  return {segment, [seg] {
            const auto result = run_segment(*seg);
            for (const auto& w : result.warnings)
              spdlog::warn(w);
            std::cout << seg->out.string() << ": " << result.volume_cm3 << " cm3\n";
            return 0;
          }};
}

}  // namespace organfit::app
