#include "organfit/pipeline/segment_command.h"

#include "organfit/dicom/structure_set.h"
#include "organfit/itkbridge/itk_images.h"
#include "organfit/segmentation/segment.h"
#include "organfit/support/error.h"
#include "organfit/support/output_folder.h"

namespace organfit::pipeline {

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
  const dicom::CtSeries ct = dicom::read_ct_series(r.ct_folder, o);
  SegmentResult result;
  result.warnings = ct.warnings;
  geometry::LabelVolume mask;
  if (import) {
    dicom::RasterisedRoi roi = dicom::rasterise_roi(dicom::read_rtstruct(r.rtstruct), r.roi, ct,
                                                    r.rtstruct.string(), r.roi_number);
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
  result.volume_cm3 = mask.volume_mm3(1) / 1000.0;
  CreatedFolders folders(r.out.parent_path().empty() ? std::filesystem::path(".")
                                                     : r.out.parent_path());
  itkbridge::write_label_volume(r.out, mask);
  folders.keep();
  return result;
}

}  // namespace organfit::pipeline
