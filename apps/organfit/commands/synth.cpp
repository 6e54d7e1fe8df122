// `organfit synth pelvis`: the pelvis phantom as a planning CT reaches us (a DICOM CT, an
// RT Structure Set of its true organs, the true labels); `organfit synth ultrasound` is in
// synth_ultrasound.cpp.
#include <spdlog/spdlog.h>

#include <iostream>
#include <memory>
#include <string>

#include "commands.h"
#include "organfit/phantom/pelvis.h"
#include "organfit/pipeline/phantom_stage.h"

namespace organfit::app {

std::vector<Command> add_synth(CLI::App& app) {
  struct Options {
    phantom::PelvisOptions pelvis;
    std::string out;
  };
  auto o = std::make_shared<Options>();
  auto* synth = app.add_subcommand("synth", "Synthetic scans with known anatomy");
  synth->require_subcommand(1);
  auto* synth_pelvis = synth->add_subcommand(
      "pelvis",
      "A pelvis phantom: DIR/ct/ (DICOM CT), DIR/rtstruct.dcm (true organs), DIR/labels.nrrd");
  synth_pelvis->add_option("-o,--out", o->out, "Output folder (created; must be empty)")
      ->required();
  synth_pelvis->add_option("--seed", o->pelvis.seed, "Seed of the noise (same seed, same files)");
  synth_pelvis->add_option("--columns", o->pelvis.columns, "Voxels along x")
      ->check(CLI::Range(8, 2048));
  synth_pelvis->add_option("--rows", o->pelvis.rows, "Voxels along y")->check(CLI::Range(8, 2048));
  synth_pelvis->add_option("--slices", o->pelvis.slices, "Slices along z, centred on the prostate")
      ->check(CLI::Range(8, 2000));
  synth_pelvis->add_option("--pixel-mm", o->pelvis.pixel_mm, "In-plane spacing (mm)")
      ->check(CLI::Range(0.1, 10.0));
  synth_pelvis->add_option("--slice-mm", o->pelvis.slice_mm, "Slice spacing (mm)")
      ->check(CLI::Range(0.1, 20.0));
  synth_pelvis->add_option("--noise-hu", o->pelvis.noise_hu, "Noise standard deviation (HU)")
      ->check(CLI::Range(0.0, 500.0));
  std::vector<Command> commands = {
      {synth_pelvis, [o] {
         const auto result = pipeline::write_pelvis_phantom(o->out, o->pelvis);
         if (result.clipped_voxels > 0)
           spdlog::warn("{} voxel(s) outside the 12-bit HU range were clipped",
                        result.clipped_voxels);
         std::cout << o->out << ": pelvis phantom, " << result.slices << " slices, prostate "
                   << result.prostate_volume_cm3 << " cm3\n";
         return 0;
       }}};
  commands.push_back(add_synth_ultrasound(*synth));
  return commands;
}

}  // namespace organfit::app
