// `organfit synth ultrasound`: B-mode images of a labelled volume (the pelvis phantom's
// labels.nrrd), its organ optionally deformed by a known volume-preserving map, as a
// probe at a given pose sees it: a 3D volume, a tracked 2D sweep and the true boundary.
#include <fmt/format.h>

#include <CLI/CLI.hpp>
#include <Eigen/Geometry>
#include <cmath>
#include <cstdint>
#include <filesystem>
#include <iostream>
#include <memory>
#include <nlohmann/json.hpp>
#include <vector>

#include "commands.h"
#include "organfit/dicom/ct_series.h"
#include "organfit/evaluation/synthetic.h"
#include "organfit/itkbridge/itk_images.h"
#include "organfit/phantom/pelvis.h"
#include "organfit/pipeline/ultrasound_stage.h"
#include "organfit/support/atomic_file.h"
#include "organfit/support/error.h"
#include "organfit/support/output_folder.h"
#include "organfit/ultrasound/sequence_metafile.h"
#include "organfit/ultrasound/simulator.h"

namespace fs = std::filesystem;

namespace organfit::app {
namespace {

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
nlohmann::json run_synth_ultrasound(const SynthUltrasoundCommand& c) {
  std::error_code ec;
  if (fs::exists(c.out, ec) && !(fs::is_directory(c.out, ec) && fs::is_empty(c.out, ec)))
    throw InputError(c.out.string() + ": exists and is not an empty folder");
  check_output_location(c.out, {c.labels, c.ct}, "--out");
  if (!(c.probe.empty() || c.probe.size() == 3 || c.probe.size() == 6 || c.probe.size() == 9))
    throw InputError("synth ultrasound: --probe takes X,Y,Z[,AX,AY,AZ[,LX,LY,LZ]]");
  if (c.sweep_frames < 1) throw InputError("synth ultrasound: --frames must be at least 1");
  const geometry::LabelVolume labels = itkbridge::read_label_volume(c.labels);
  const auto& g = labels.geometry;
  // HU for shadows: the CT's when given (same grid), else bone from the labels.
  std::vector<float> hu(labels.labels.size(), 0.0f);
  if (!c.ct.empty()) {
    const dicom::CtSeries ct = dicom::read_ct_series(c.ct);
    if (ct.geometry.size != g.size)
      throw InputError(c.ct.string() + ": the CT's grid is not the labels'");
    hu = ct.hu;
  } else {
    for (size_t v = 0; v < hu.size(); ++v) {
      const auto l = labels.labels[v];
      hu[v] = l == phantom::kPelvicBone || l == phantom::kFemurLeft || l == phantom::kFemurRight
                  ? 1000.0f
              : l == phantom::kAir ? -1000.0f
                                   : 0.0f;
    }
  }
  geometry::LabelVolume organ_mask(g);
  for (size_t v = 0; v < labels.labels.size(); ++v)
    organ_mask.labels[v] = labels.labels[v] == c.organ_label;
  if (organ_mask.count(1) == 0)
    throw InputError(
        fmt::format("{}: no voxel has the organ label {}", c.labels.string(), c.organ_label));
  const geometry::Shape organ =
      geometry::make_mask_shape(std::make_shared<const geometry::LabelVolume>(organ_mask));
  evaluation::Deformation d;
  d.stretch = c.stretch, d.bend_mm = c.bend_mm, d.centre_mm = organ.centre_mm;
  d.half_length_mm = 0.5 * organ.size_mm.x() * d.stretch;
  const geometry::LabelVolume tissue = pipeline::pelvis_tissue_classes(labels);

  ultrasound::ProbePose probe = pipeline::transrectal_probe_pose();
  probe.position_mm += organ.centre_mm;
  if (c.probe.size() >= 3) probe.position_mm = Eigen::Vector3d(c.probe[0], c.probe[1], c.probe[2]);
  if (c.probe.size() >= 6)
    probe.axis = Eigen::Vector3d(c.probe[3], c.probe[4], c.probe[5]).normalized();
  if (c.probe.size() == 9)
    probe.lateral = Eigen::Vector3d(c.probe[6], c.probe[7], c.probe[8]).normalized();
  ultrasound::SimulatorOptions so = pipeline::tissue_class_simulator_options();
  so.speckle = c.speckle;
  so.seed = c.seed;
  const ultrasound::TissueAt today = pipeline::deformed_anatomy(tissue, hu, organ, d);
  ultrasound::SimulatedUltrasound sim;
  try {
    sim = ultrasound::simulate_bmode(today, probe, so);
  } catch (const std::invalid_argument& e) {
    throw InputError(std::string("synth ultrasound: ") + e.what());
  }

  // The tracked sweep: a fan of planes through the probe, tilted about its lateral
  // direction, each sampled from the volume (nearest voxel) at the volume's spacing.
  const double px = so.voxel_mm;
  const int width = static_cast<int>(
      std::ceil(2 * so.max_depth_mm * std::tan(so.lateral_half_angle_deg * M_PI / 180) / px));
  const int height = static_cast<int>(std::ceil(so.max_depth_mm / px));
  const Eigen::Vector3d elevation = probe.axis.cross(probe.lateral);
  ultrasound::TrackedSweep sweep;
  for (int f = 0; f < c.sweep_frames; ++f) {
    const double tilt =
        c.sweep_frames == 1 ? 0.0 : (-40.0 + 80.0 * f / (c.sweep_frames - 1)) * M_PI / 180;
    const Eigen::Vector3d beam = std::cos(tilt) * probe.axis + std::sin(tilt) * elevation;
    ultrasound::TrackedFrame frame;
    frame.index = f;
    frame.timestamp_s = 0.1 * f;
    frame.width = width, frame.height = height;
    frame.pixel_to_ct_mm.setIdentity();
    frame.pixel_to_ct_mm.block<3, 1>(0, 0) = px * probe.lateral;
    frame.pixel_to_ct_mm.block<3, 1>(0, 1) = px * beam;
    frame.pixel_to_ct_mm.block<3, 1>(0, 2) = probe.lateral.cross(beam);
    frame.pixel_to_ct_mm.block<3, 1>(0, 3) = probe.position_mm - 0.5 * width * px * probe.lateral;
    frame.pixels.assign(static_cast<size_t>(width) * height, 0.0f);
    for (int r = 0; r < height; ++r)
      for (int col = 0; col < width; ++col) {
        const Eigen::Vector3d p = (frame.pixel_to_ct_mm * Eigen::Vector4d(col, r, 0, 1)).head<3>();
        const Eigen::Vector3d idx = sim.geometry.physical_to_index(p);
        const int i = static_cast<int>(std::lround(idx.x())),
                  j = static_cast<int>(std::lround(idx.y())),
                  k = static_cast<int>(std::lround(idx.z()));
        if (i < 0 || j < 0 || k < 0 || i >= sim.geometry.size[0] || j >= sim.geometry.size[1] ||
            k >= sim.geometry.size[2])
          continue;
        frame.pixels[static_cast<size_t>(r) * width + col] =
            sim.bmode[static_cast<size_t>(sim.geometry.linear_index(i, j, k))];
      }
    sweep.frames.push_back(std::move(frame));
  }

  OutputFolder folder(c.out, {});  // written whole or not at all
  const fs::path& dir = folder.staging();
  geometry::LabelVolume volume(sim.geometry);
  volume.labels = sim.bmode;
  itkbridge::write_label_volume(dir / "volume.mha", volume);
  ultrasound::write_sequence_metafile(dir / "sweep.igs.mha", sweep, px);
  std::string csv = "x_mm,y_mm,z_mm\n";
  for (const auto& p : sim.true_boundary_mm)
    csv += fmt::format("{:.3f},{:.3f},{:.3f}\n", p.x(), p.y(), p.z());
  write_file_atomically(dir / "true_boundary.csv", csv);
  nlohmann::json summary = {
      {"labels", c.labels.string()},
      {"seed", c.seed},
      {"speckle", c.speckle},
      {"organ_label", c.organ_label},
      {"organ_centre_mm", {organ.centre_mm.x(), organ.centre_mm.y(), organ.centre_mm.z()}},
      {"deformation", {{"stretch", c.stretch}, {"bend_mm", c.bend_mm}}},
      {"probe_mm", {probe.position_mm.x(), probe.position_mm.y(), probe.position_mm.z()}},
      {"probe_axis", {probe.axis.x(), probe.axis.y(), probe.axis.z()}},
      {"volume_size", {sim.geometry.size[0], sim.geometry.size[1], sim.geometry.size[2]}},
      {"sweep_frames", sweep.frames.size()},
      {"frame_size", {width, height}},
      {"true_boundary_points", sim.true_boundary_mm.size()},
      {"files", {"volume.mha", "sweep.igs.mha", "true_boundary.csv"}}};
  write_file_atomically(dir / "ultrasound.json", summary.dump(2) + "\n");
  folder.commit();
  return summary;
}

}  // namespace

Command add_synth_ultrasound(CLI::App& synth) {
  auto sus = std::make_shared<SynthUltrasoundCommand>();
  auto* synth_us = synth.add_subcommand("ultrasound",
                                        "B-mode of a labelled volume (e.g. the phantom, organ "
                                        "deformed): volume, tracked sweep, true boundary");
  synth_us->add_option("--labels", sus->labels, "Label volume (the phantom's labels.nrrd)")
      ->required();
  synth_us->add_option("--ct", sus->ct, "CT folder on the same grid (HU for gas and bone shadows)");
  synth_us
      ->add_option("--probe", sus->probe,
                   "Probe X,Y,Z[,AX,AY,AZ[,LX,LY,LZ]] mm (default: transrectal)")
      ->delimiter(',');
  synth_us->add_option("-o,--out", sus->out, "Output folder (created; must be empty)")->required();
  synth_us->add_option("--seed", sus->seed, "Seed of the speckle");
  synth_us->add_option("--stretch", sus->stretch, "Organ stretch along x (volume-preserving)")
      ->check(CLI::Range(0.5, 2.0));
  synth_us->add_option("--bend", sus->bend_mm, "Organ bend (mm)")->check(CLI::Range(-30.0, 30.0));
  synth_us
      ->add_option("--organ-label", sus->organ_label,
                   "Label of the organ (8: the phantom's prostate)")
      ->check(CLI::Range(1, 255));
  synth_us->add_option("--speckle", sus->speckle, "Speckle level 0..1")
      ->check(CLI::Range(0.0, 1.0));
  synth_us->add_option("--frames", sus->sweep_frames, "Frames of the tracked sweep")
      ->check(CLI::Range(1, 2000));
  return {synth_us, [sus] {
            std::cout << run_synth_ultrasound(*sus).dump() << "\n";
            return 0;
          }};
}

}  // namespace organfit::app
