#pragma once
// `organfit synth ultrasound`: B-mode images of a labelled volume (the pelvis phantom's
// labels.nrrd), its organ optionally deformed by a known volume-preserving map, as a
// probe at a given pose sees it: a 3D volume, a tracked 2D sweep and the true boundary.
#include <cstdint>
#include <filesystem>
#include <nlohmann/json.hpp>
#include <vector>

namespace organfit::pipeline {

struct SynthUltrasoundCommand {
  std::filesystem::path labels;  ///< phantom labels (phantom::PelvisLabel)
  std::filesystem::path ct;      ///< optional CT folder: HU for gas and bone shadows
  std::vector<double> probe;  ///< X,Y,Z[,AX,AY,AZ[,LX,LY,LZ]]; empty: transrectal at the prostate
  std::filesystem::path out;  ///< folder (created; must be empty)
  std::uint64_t seed = 1;
  double stretch = 1.0, bend_mm = 0.0;  ///< the organ's known deformation
  int organ_label = 8;                  ///< the prostate
  double speckle = 1.0;
  int sweep_frames = 41;  ///< frames of the tracked sweep (a fan of +-40 degrees)
};

/// Writes OUT/volume.mha (8-bit B-mode, CT axes), OUT/sweep.igs.mha (sequence metafile,
/// ImageToReferenceTransform per frame, reference = CT), OUT/true_boundary.csv (the organ's
/// surface the probe sees), OUT/ultrasound.json. Deterministic for a seed. Returns the
/// summary. Throws InputError on bad input.
nlohmann::json run_synth_ultrasound(const SynthUltrasoundCommand& command);

}  // namespace organfit::pipeline
