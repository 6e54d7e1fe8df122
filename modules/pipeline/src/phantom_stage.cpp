#include "organfit/pipeline/phantom_stage.h"

#include <fmt/format.h>

#include <nlohmann/json.hpp>

#include "organfit/dicom/ct_writer.h"
#include "organfit/dicom/rtstruct_writer.h"
#include "organfit/itkbridge/itk_images.h"
#include "organfit/pipeline/scene_schema.h"
#include "organfit/support/atomic_file.h"
#include "organfit/support/error.h"
#include "organfit/support/output_folder.h"

namespace fs = std::filesystem;

namespace organfit::pipeline {

SynthResult write_pelvis_phantom(const fs::path& out, const phantom::PelvisOptions& options) {
  std::error_code ec;
  if (fs::exists(out, ec) && !(fs::is_directory(out, ec) && fs::is_empty(out, ec)))
    throw InputError(out.string() + ": exists and is not an empty folder");
  check_output_location(out, {}, "--out");
  OutputFolder folder(out, {});  // written whole or not at all
  const fs::path& dir = folder.staging();

  phantom::PelvisPhantom ph = phantom::make_pelvis_phantom(options);
  const std::string key = fmt::format("organfit-pelvis|{}|{}x{}x{}|{}|{}|{}", options.seed,
                                      options.columns, options.rows, options.slices,
                                      options.pixel_mm, options.slice_mm, options.noise_hu);
  dicom::CtSeries ct;
  ct.geometry = ph.geometry;
  ct.hu = std::move(ph.hu);
  ct.series_description = "organfit synthetic pelvis";
  ct.patient.patient_name = "Phantom^Pelvis";
  ct.patient.patient_id = fmt::format("PELVIS-{}", options.seed);
  ct.patient.patient_sex = "M";
  ct.patient.study_id = "1";
  ct.patient.study_description = "organfit synthetic pelvis";
  dicom::CtWriteOptions write;
  write.fixed_uids_and_dates = true;  // a phantom is reproducible to the byte
  write.uid_key = key;
  write.body_part_examined = "PELVIS";
  SynthResult result;
  result.clipped_voxels = dicom::write_ct_series(dir / "ct", ct, write);
  result.slices = ph.geometry.size[2];

  std::vector<dicom::RtstructRoi> rois;
  for (const auto& s : phantom::pelvis_structures()) {
    dicom::RtstructRoi roi;
    roi.name = s.name;
    roi.colour = s.colour;
    roi.interpreted_type = s.interpreted_type;
    roi.contours = phantom::pelvis_true_contours(ph.labels, s);
    rois.push_back(std::move(roi));
  }
  dicom::RtstructWriteOptions rt;
  rt.label = "TRUTH";
  rt.series_description = "organfit phantom: true structures";
  rt.fixed_uids_and_dates = true;
  dicom::write_rtstruct(dir / "rtstruct.dcm", ct, rois, rt);
  itkbridge::write_label_volume(dir / "labels.nrrd", ph.labels);

  result.prostate_volume_cm3 = ph.labels.volume_mm3(phantom::kProstate) / 1000.0;
  nlohmann::ordered_json j;
  j["phantom"] = "pelvis";
  j["seed"] = options.seed;
  j["size"] = {options.columns, options.rows, options.slices};
  j["spacing_mm"] = {options.pixel_mm, options.pixel_mm, options.slice_mm};
  j["noise_hu"] = options.noise_hu;
  j["prostate_centre_mm"] = {ph.prostate_centre_mm.x(), ph.prostate_centre_mm.y(),
                             ph.prostate_centre_mm.z()};
  nlohmann::ordered_json structures = nlohmann::ordered_json::array();
  for (const auto& s : phantom::pelvis_structures()) {
    const double voxels =
        s.label == phantom::kAir
            ? static_cast<double>(ph.labels.labels.size() - ph.labels.count(phantom::kAir))
            : static_cast<double>(ph.labels.count(s.label));
    structures.push_back({{"roi", s.name},
                          {"label", s.label == phantom::kAir ? nlohmann::ordered_json("all but 0")
                                                             : nlohmann::ordered_json(s.label)},
                          {"volume_cm3", voxels * ph.geometry.voxel_volume_mm3() / 1000.0}});
  }
  j["structures"] = structures;
  j["files"] = {{"ct", "ct/"}, {"rtstruct", "rtstruct.dcm"}, {"labels", "labels.nrrd"}};
  write_file_atomically(dir / "phantom.json", j.dump(2) + "\n");
  folder.commit();
  return result;
}

phantom::PelvisOptions phantom_options_from(const config::Scene& scene) {
  return keys::phantom().read(scene);
}

}  // namespace organfit::pipeline
