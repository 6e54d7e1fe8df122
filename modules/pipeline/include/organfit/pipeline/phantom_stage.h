#pragma once
// The phantom stage (and `organfit synth pelvis`): the synthetic pelvis phantom written
// as a planning CT would reach us: a DICOM CT series, an RT Structure Set of the true
// organs, and the true label volume.
#include <cstdint>
#include <filesystem>
#include <string>

#include "organfit/config/scene.h"
#include "organfit/phantom/pelvis.h"

namespace organfit::pipeline {

struct SynthResult {
  double prostate_volume_cm3 = 0;  ///< true label volume (voxel centres)
  int slices = 0;
  long long clipped_voxels = 0;
};

/// Writes into `out` (created; must not exist or be empty):
///   ct/            the CT series, one file per slice
///   rtstruct.dcm   the true structures (Body, Bladder, Rectum, Prostate, ...)
///   labels.nrrd    the true label volume on the CT grid (phantom::PelvisLabel)
///   phantom.json   what was made: options, labels, volumes, the prostate's centre
/// The same seed and options give byte-identical files (UIDs derived from them).
/// Throws InputError naming `out` when it cannot be written.
SynthResult write_pelvis_phantom(const std::filesystem::path& out,
                                 const phantom::PelvisOptions& options);

/// The scene's `phantom` section as the phantom's options.
phantom::PelvisOptions phantom_options_from(const config::Scene& scene);

}  // namespace organfit::pipeline
