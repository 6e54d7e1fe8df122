// organfit: prepare a radiotherapy session by fitting a particle-system organ model to
// sparse ultrasound points. Subcommands in the style of git / plastimatch.
//
// Exit codes: 0 success, 1 internal error, 2 bad input (usage, scene, data, a DICOM node
// that cannot be reached, refuses or fails),
// 3 ran but did not meet its target. Errors are one line on stderr.
#include <CLI/CLI.hpp>
#include <iostream>

#include "organfit/evaluation/cohesion_benchmark.h"
#include "organfit/evaluation/skeleton_benchmark.h"
#include "organfit/pipeline/ct_benchmark.h"
#include "organfit/pipeline/dicom_command.h"
#include "organfit/pipeline/export_command.h"
#include "organfit/pipeline/fit_benchmark.h"
#include "organfit/pipeline/runner.h"
#include "organfit/pipeline/scale_benchmark.h"
#include "organfit/pipeline/scene_schema.h"
#include "organfit/pipeline/segment_command.h"
#include "organfit/pipeline/stability_benchmark.h"
#include "organfit/pipeline/synth_command.h"
#include "organfit/pipeline/synth_ultrasound_command.h"
#include "organfit/pipeline/us_benchmark.h"
#include "organfit/pipeline/us_points_command.h"
#include "organfit/support/error.h"
#include "organfit/support/interrupt.h"
#include "organfit/support/log.h"
#include "organfit/support/progress.h"

namespace {

using organfit::ExitCode;

int run_main(int argc, char** argv) {
  CLI::App app{"organfit: fit a particle-system organ model to sparse ultrasound points"};
  app.require_subcommand(1);
  app.fallthrough();
  bool quiet = false, verbose = false;
  app.add_flag("-q,--quiet", quiet, "Only warnings and errors; no progress");
  app.add_flag("-v,--verbose", verbose, "More detail in logs and errors");
  organfit::pipeline::RunOptions run_options;
  app.add_flag("--show-phi", run_options.show_phi,
               "Allow the patient's name, ID and birth date in the report (report.show_patient); "
               "never in logs");

  std::string scene_file, out_dir;
  std::vector<std::string> overrides;
  auto* run = app.add_subcommand("run", "Run a scene: the stages it names, outputs into --out");
  run->add_option("scene", scene_file, "Scene file (YAML)")->required();
  auto add_set = [&overrides](CLI::App* command) {
    command
        ->add_option("--set", overrides,
                     "section.key=value: sets a scene key for this run (repeatable; validated "
                     "as the file is; recorded in resolved.yaml)")
        ->expected(1)
        ->multi_option_policy(CLI::MultiOptionPolicy::TakeAll);
  };
  add_set(run);
  run->add_option("-o,--out", out_dir, "Output folder (created; not the scene's folder)")
      ->required();

  auto* validate = app.add_subcommand("validate", "Check a scene without running it");
  validate->add_option("scene", scene_file, "Scene file (YAML)")->required();
  add_set(validate);

  bool schema_json = false;
  auto* schema =
      app.add_subcommand("schema", "Print every scene key: type, default, unit, range, doc");
  schema->add_flag("--json", schema_json, "As JSON");

  auto* version = app.add_subcommand("version", "Print the organfit version");

  organfit::pipeline::SegmentRequest seg;
  auto* segment = app.add_subcommand(
      "segment", "An organ mask from a CT: imported from an RTSTRUCT or grown from a seed");
  segment->add_option("--ct", seg.ct_folder, "Folder of the CT series")->required();
  segment->add_option("--series-uid", seg.series_uid,
                      "Series Instance UID when the folder holds several CT series");
  segment->add_option("--rtstruct", seg.rtstruct, "RT Structure Set to import from");
  segment->add_option("--roi", seg.roi, "ROI name in the structure set");
  segment
      ->add_option("--roi-number", seg.roi_number,
                   "ROI Number in the structure set, when several ROIs share the name")
      ->check(CLI::PositiveNumber);
  segment->add_option("--seed", seg.seed_mm, "Seed X,Y,Z in mm (patient LPS)")
      ->delimiter(',')
      ->expected(3);
  segment->add_option("--hu", seg.hu_window, "HU window LOW,HIGH")->delimiter(',')->expected(2);
  segment
      ->add_option("--search-box", seg.search_box_mm,
                   "Side (mm) of the cube around the seed grown in; 0 = whole CT")
      ->check(CLI::Range(0.0, 2000.0));
  segment->add_option("-o,--out", seg.out, "Mask file (.nrrd, .mha, .nii, .nii.gz)")->required();

  organfit::pipeline::ExportCommand exp;
  auto* export_cmd = app.add_subcommand(
      "export", "Write a saved model for the planning system: RTSTRUCT, label map, mesh");
  export_cmd->add_option("--model", exp.model, "Model file (a scene's export.model)")->required();
  export_cmd->add_option("--ct", exp.ct,
                         "Planning CT folder (default: the one the model was built on)");
  export_cmd->add_option("--rtstruct", exp.rtstruct, "RT Structure Set to write (.dcm)");
  export_cmd->add_option("--labels", exp.labels, "Label map to write (.nrrd, .mha, .nii, .nii.gz)");
  export_cmd->add_option("--mesh", exp.mesh, "Surface mesh to write (.stl, .vtp, .ply, .obj)");
  export_cmd->add_option("--displacement-field", exp.displacement_field,
                         "Deformation field to write on the planning CT's grid (.mha, .nrrd): "
                         "phi^-1(q) - q, as plastimatch warp --xf reads it");
  export_cmd->add_option("--registration", exp.registration,
                         "DICOM Deformable Spatial Registration (REG) to write: the same field");
  export_cmd
      ->add_option("--field-spacing", exp.field_spacing_mm,
                   "Grid of the field, REG and Jacobian (mm; 0: the CT's grid)")
      ->check(CLI::Range(0.0, 50.0));
  export_cmd->add_option("--jacobian", exp.jacobian,
                         "det(grad phi) to write on the planning CT's grid (.nrrd, .mha)");
  export_cmd->add_option("--roi-name", exp.roi_name,
                         "Name of the exported ROI (default: the organ's name + _fit)");
  export_cmd->add_option("--copy-rois-from", exp.copy_rois_from,
                         "RT Structure Set whose other ROIs are copied alongside");

  organfit::pipeline::UsPointsCommand usp;
  auto* us_points = app.add_subcommand(
      "us-points", "Boundary points of an ultrasound volume, tracked sweep or DICOM image (CSV)");
  us_points
      ->add_option("--us", usp.input,
                   "Ultrasound input: volume (.mha .nrrd .nii), sequence metafile, or .dcm")
      ->required();
  us_points->add_option("--tracker", usp.tracker,
                        "Sequence metafile with the probe poses (matched by timestamp)");
  us_points->add_option("--transform", usp.transform,
                        "Tracked transform name (default: the file's own)");
  us_points
      ->add_option("--calibration", usp.calibration, "Image (mm) to probe, 16 numbers row by row")
      ->delimiter(',')
      ->expected(16);
  us_points
      ->add_option("--registration", usp.registration, "Tracker/volume to CT, 16 numbers (rigid)")
      ->delimiter(',')
      ->expected(16);
  us_points
      ->add_option("--pixel-mm", usp.pixel_mm,
                   "Pixel size of a DICOM image without calibrated region")
      ->check(CLI::PositiveNumber);
  us_points
      ->add_option("--centre", usp.centre_mm,
                   "Region of interest centre X,Y,Z (mm, output coordinates)")
      ->delimiter(',')
      ->expected(3);
  us_points->add_option("--radius", usp.radius_mm, "Region of interest radius (mm)")
      ->check(CLI::PositiveNumber);
  us_points->add_option("--count", usp.count, "Points to keep (0: all)")
      ->check(CLI::Range(0, 100000));
  us_points->add_option("--rays", usp.rays, "Search rays (3D volumes)")
      ->check(CLI::Range(16, 100000));
  us_points->add_option("--ct", usp.ct,
                        "The CT folder --registration maps into: its series is declared in the "
                        "CSV, and a run refuses the points with another planning CT");
  us_points->add_option("-o,--out", usp.out, "Points CSV (x_mm,y_mm,z_mm,confidence)")->required();

  auto* synth = app.add_subcommand("synth", "Synthetic scans with known anatomy");
  synth->require_subcommand(1);
  organfit::phantom::PelvisOptions pelvis;
  std::string synth_out;
  auto* synth_pelvis = synth->add_subcommand(
      "pelvis",
      "A pelvis phantom: DIR/ct/ (DICOM CT), DIR/rtstruct.dcm (true organs), DIR/labels.nrrd");
  synth_pelvis->add_option("-o,--out", synth_out, "Output folder (created; must be empty)")
      ->required();
  synth_pelvis->add_option("--seed", pelvis.seed, "Seed of the noise (same seed, same files)");
  synth_pelvis->add_option("--columns", pelvis.columns, "Voxels along x")
      ->check(CLI::Range(8, 2048));
  synth_pelvis->add_option("--rows", pelvis.rows, "Voxels along y")->check(CLI::Range(8, 2048));
  synth_pelvis->add_option("--slices", pelvis.slices, "Slices along z, centred on the prostate")
      ->check(CLI::Range(8, 2000));
  synth_pelvis->add_option("--pixel-mm", pelvis.pixel_mm, "In-plane spacing (mm)")
      ->check(CLI::Range(0.1, 10.0));
  synth_pelvis->add_option("--slice-mm", pelvis.slice_mm, "Slice spacing (mm)")
      ->check(CLI::Range(0.1, 20.0));
  synth_pelvis->add_option("--noise-hu", pelvis.noise_hu, "Noise standard deviation (HU)")
      ->check(CLI::Range(0.0, 500.0));

  organfit::pipeline::SynthUltrasoundCommand sus;
  auto* synth_us = synth->add_subcommand("ultrasound",
                                         "B-mode of a labelled volume (e.g. the phantom, organ "
                                         "deformed): volume, tracked sweep, true boundary");
  synth_us->add_option("--labels", sus.labels, "Label volume (the phantom's labels.nrrd)")
      ->required();
  synth_us->add_option("--ct", sus.ct, "CT folder on the same grid (HU for gas and bone shadows)");
  synth_us
      ->add_option("--probe", sus.probe,
                   "Probe X,Y,Z[,AX,AY,AZ[,LX,LY,LZ]] mm (default: transrectal)")
      ->delimiter(',');
  synth_us->add_option("-o,--out", sus.out, "Output folder (created; must be empty)")->required();
  synth_us->add_option("--seed", sus.seed, "Seed of the speckle");
  synth_us->add_option("--stretch", sus.stretch, "Organ stretch along x (volume-preserving)")
      ->check(CLI::Range(0.5, 2.0));
  synth_us->add_option("--bend", sus.bend_mm, "Organ bend (mm)")->check(CLI::Range(-30.0, 30.0));
  synth_us
      ->add_option("--organ-label", sus.organ_label,
                   "Label of the organ (8: the phantom's prostate)")
      ->check(CLI::Range(1, 255));
  synth_us->add_option("--speckle", sus.speckle, "Speckle level 0..1")->check(CLI::Range(0.0, 1.0));
  synth_us->add_option("--frames", sus.sweep_frames, "Frames of the tracked sweep")
      ->check(CLI::Range(1, 2000));

  auto* bench = app.add_subcommand("bench", "Benchmarks; print machine-readable JSON on stdout");
  bench->require_subcommand(1);
  organfit::evaluation::CohesionBenchOptions cb;
  bool scaling = false, no_lammps = false;
  auto* bench_cohesion = bench->add_subcommand(
      "cohesion", "LJ cohesion on the LAMMPS in.lj system, side by side with LAMMPS");
  bench_cohesion->add_option("--particles", cb.particles, "Particle count (whole fcc cells)")
      ->check(CLI::Range(4LL, 50000000LL));
  bench_cohesion->add_option("--steps", cb.steps, "Steps")->check(CLI::Range(1LL, 1000000LL));
  bench_cohesion->add_option("--threads", cb.threads, "OpenMP threads")->check(CLI::Range(1, 256));
  bench_cohesion->add_flag("--scaling", scaling,
                           "Cost per particle-step from 1e3 to 1e6 particles");
  bench_cohesion->add_flag("--no-lammps", no_lammps, "Do not run LAMMPS alongside");

  organfit::evaluation::SkeletonBenchOptions sb;
  auto* bench_skeleton = bench->add_subcommand(
      "skeleton", "Shape kept with the skeleton vs rounding up without, in a fluid-like state");
  bench_skeleton->add_option("--steps", sb.steps, "Thermostat steps")
      ->check(CLI::Range(1LL, 100000000LL));
  bench_skeleton->add_option("--temperature", sb.temperature, "kT in units of E0")
      ->check(CLI::Range(0.0, 10.0));
  bench_skeleton->add_option("--friction", sb.friction, "Thermostat friction K_a/M (1/s)")
      ->check(CLI::PositiveNumber);
  bench_skeleton
      ->add_option("--stiffness", sb.stiffness_fraction, "Skeleton stiffness / LJ stiffness")
      ->check(CLI::PositiveNumber);
  bench_skeleton->add_option("--node-spacing", sb.node_spacing_r0, "Skeleton node spacing (r0)")
      ->check(CLI::PositiveNumber);
  bench_skeleton->add_option("--length", sb.size_x_mm, "Ellipsoid length (mm)")
      ->check(CLI::PositiveNumber);
  bench_skeleton->add_option("--width", sb.size_yz_mm, "Ellipsoid width (mm)")
      ->check(CLI::PositiveNumber);
  bench_skeleton->add_option("--threads", sb.threads, "OpenMP threads")->check(CLI::Range(1, 256));

  organfit::pipeline::CtBenchOptions ctb;
  auto* bench_ct = bench->add_subcommand(
      "ct", "CT stage on a 512x512x100 CT: read + segment + skeleton + seed, with peak memory");
  bench_ct->add_option("--ct", ctb.ct, "CT folder (default: a pelvis phantom made first)");
  bench_ct->add_option("--columns", ctb.columns, "Phantom columns")->check(CLI::Range(64, 2048));
  bench_ct->add_option("--rows", ctb.rows, "Phantom rows")->check(CLI::Range(64, 2048));
  bench_ct->add_option("--slices", ctb.slices, "Phantom slices")->check(CLI::Range(8, 2000));
  bench_ct->add_option("--seed", ctb.seed_mm, "Organ seed X,Y,Z (mm)")->delimiter(',')->expected(3);
  bench_ct->add_option("--hu", ctb.hu_window, "Organ HU window LO,HI")->delimiter(',')->expected(2);
  bench_ct->add_option("--radius", ctb.radius_mm, "Particle radius (mm)")
      ->check(CLI::Range(0.3, 20.0));
  bench_ct->add_option("--threads", ctb.threads, "OpenMP threads (0: all)")
      ->check(CLI::Range(0, 256));

  organfit::pipeline::UsBenchOptions usb;
  auto* bench_us =
      bench->add_subcommand("us", "Ultrasound segmentation: a 256^3 volume and a 100-frame sweep");
  bench_us->add_option("--size", usb.volume_size, "Volume voxels per side")
      ->check(CLI::Range(32, 1024));
  bench_us->add_option("--frames", usb.frames, "Sweep frames")->check(CLI::Range(1, 10000));
  bench_us->add_option("--threads", usb.threads, "OpenMP threads (0: all)")
      ->check(CLI::Range(0, 256));

  organfit::pipeline::FitBenchOptions fb;
  auto* bench_fit = bench->add_subcommand(
      "fit", "Error against run time: the particle fits and TPS, CPD, ICP on known deformations");
  bench_fit
      ->add_option("-o,--out", fb.out,
                   "Output folder: results.csv, curves.csv, work_precision.svg, RESULTS.md")
      ->required();
  bench_fit->add_flag("--quick", fb.quick, "The quick grid (20 cases, a few minutes on 2 cores)");
  bench_fit->add_flag("--fem", fb.fem,
                      "The biomechanical ground truth: the prostate and real GTVs deformed by a "
                      "FEM engine (GetFEM) under a probe and bladder filling, 2 to 12 mm (24 "
                      "cases; solved once, then cached)");
  bench_fit->add_option("--fem-cache", fb.fem_cache,
                        "Folder of the FEM cases (default $ORGANFIT_FEM_CACHE, else "
                        "~/.cache/organfit/fem)");
  bench_fit->add_flag("--sessions", fb.sessions,
                      "The regime of treatment sessions: rigid shifts and rotations and every "
                      "family at 0 to 5 mm (70 cases), with do-no-harm counts");
  bench_fit->add_option("--threads", fb.threads, "OpenMP threads (0: all)")
      ->check(CLI::Range(0, 256));
  bench_fit
      ->add_option("--sample", fb.sample,
                   "Run N cases, a seeded uniform sample of the grid (0: all)")
      ->check(CLI::Range(0LL, 1000000LL));
  bench_fit->add_flag("--targets", fb.targets,
                      "Only the cases the targets name (<= 87 points, 0.5 mm noise, no outliers, "
                      "<= 10 mm): 225 of the grid's 2,400");
  bench_fit
      ->add_option("--cases", fb.cases,
                   "Only these cases, comma-separated, by their number in the grid (results.csv's "
                   "case column)")
      ->delimiter(',');
  bench_fit
      ->add_option(
          "--methods", fb.methods,
          "Only these methods, comma-separated: spread, paper, tps, cpd, icp (default: all)")
      ->delimiter(',');
  bench_fit->add_flag("--defaults-only", fb.defaults_only,
                      "Each method at its default setting only (the same results.csv rows; no "
                      "work-precision settings besides)");

  organfit::pipeline::ScaleBenchOptions scb;
  auto* bench_scale = bench->add_subcommand(
      "scale", "Organs from 35 cm3 to 2.3 L and 1M particles: each stage's time and memory");
  bench_scale->add_option("-o,--out", scb.out, "Output folder (new): scenes, runs, scale.json")
      ->required();
  bench_scale
      ->add_option("--cases", scb.cases,
                   "Only these, comma-separated: prostate, gtv, lung, million (default: all)")
      ->delimiter(',');
  bench_scale->add_option("--threads", scb.threads, "OpenMP threads of each run (0: all)")
      ->check(CLI::Range(0, 256));

  organfit::pipeline::StabilityBenchOptions stb;
  auto* bench_stability = bench->add_subcommand(
      "stability", "Stiff and extreme cases, both fitting methods: a pass/fail table");
  bench_stability->add_option("-o,--out", stb.out, "Output folder: stability.csv, STABILITY.md")
      ->required();
  bench_stability->add_option("--threads", stb.threads, "OpenMP threads (0: all)")
      ->check(CLI::Range(0, 256));

  organfit::pipeline::DicomCommand dcm;
  auto* dicom = app.add_subcommand(
      "dicom",
      "A DICOM node by hand (echo, find, pull, push), as ct.node and export.send_to use it");
  dicom->require_subcommand(1);
  auto add_node = [&dcm](CLI::App* command) {
    command->add_option("node", dcm.node, "The node: AET@host:port")->required();
    command->add_option("--aet", dcm.network.calling_aet, "Our own AE title");
    command->add_option("--timeout", dcm.network.timeout_s, "Seconds before a silent node fails")
        ->check(CLI::Range(0.1, 600.0));
  };
  auto add_query = [&dcm](CLI::App* command) {
    command->add_option("--patient-id", dcm.query.patient_id, "Patient ID (never printed)");
    command->add_option("--study", dcm.query.study_uid, "Study Instance UID");
    command->add_option("--series", dcm.query.series_uid, "Series Instance UID");
    command->add_option("--modality", dcm.query.modality,
                        "Only series of this modality (CT, RTSTRUCT, ...)");
  };
  auto* dicom_echo = dicom->add_subcommand("echo", "C-ECHO: does the node answer");
  add_node(dicom_echo);
  auto* dicom_find =
      dicom->add_subcommand("find", "C-FIND: the series of a patient or a study (no names)");
  add_node(dicom_find);
  add_query(dicom_find);
  dicom_find->add_flag("--json", dcm.json, "As JSON");
  auto* dicom_pull = dicom->add_subcommand(
      "pull", "C-FIND, then C-GET of each matching series into OUT/<series UID>/");
  add_node(dicom_pull);
  add_query(dicom_pull);
  dicom_pull->add_option("-o,--out", dcm.out, "Output folder (created)")->required();
  auto* dicom_push = dicom->add_subcommand("push", "C-STORE of DICOM files (or folders of them)");
  add_node(dicom_push);
  dicom_push->add_option("files", dcm.files, "Files or folders")->required();

  try {
    app.parse(argc, argv);
  } catch (const CLI::CallForHelp& e) {
    return app.exit(e);
  } catch (const CLI::CallForAllHelp& e) {
    return app.exit(e);
  } catch (const CLI::ParseError& e) {
    std::cerr << "organfit: usage: " << e.what() << " (see organfit --help)\n";
    return static_cast<int>(ExitCode::kBadInput);
  }

  organfit::install_interrupt_handlers();
  organfit::setup_logging(quiet     ? organfit::Verbosity::kQuiet
                          : verbose ? organfit::Verbosity::kVerbose
                                    : organfit::Verbosity::kNormal);
  organfit::Progress::set_enabled(!quiet);

  if (*dicom_echo) {
    organfit::pipeline::run_dicom_echo(dcm);
  } else if (*dicom_find) {
    organfit::pipeline::run_dicom_find(dcm);
  } else if (*dicom_pull) {
    organfit::pipeline::run_dicom_pull(dcm);
  } else if (*dicom_push) {
    organfit::pipeline::run_dicom_push(dcm);
  } else if (*version) {
    std::cout << "organfit " << organfit::pipeline::version() << "\n";
  } else if (*schema) {
    const auto& s = organfit::pipeline::scene_schema();
    std::cout << (schema_json ? s.to_json().dump(2) + "\n" : s.to_text());
  } else if (*segment) {
    const auto result = organfit::pipeline::run_segment(seg);
    for (const auto& w : result.warnings)
      spdlog::warn(w);
    std::cout << seg.out.string() << ": " << result.volume_cm3 << " cm3\n";
  } else if (*us_points) {
    std::cout << organfit::pipeline::run_us_points(usp).dump() << "\n";
  } else if (*export_cmd) {
    const auto summary = organfit::pipeline::run_export_command(exp);
    std::cout << summary.dump() << "\n";
  } else if (*synth_us) {
    std::cout << organfit::pipeline::run_synth_ultrasound(sus).dump() << "\n";
  } else if (*synth_pelvis) {
    const auto result = organfit::pipeline::run_synth_pelvis(synth_out, pelvis);
    if (result.clipped_voxels > 0)
      spdlog::warn("{} voxel(s) outside the 12-bit HU range were clipped", result.clipped_voxels);
    std::cout << synth_out << ": pelvis phantom, " << result.slices << " slices, prostate "
              << result.prostate_volume_cm3 << " cm3\n";
  } else if (*validate) {
    const auto scene = organfit::pipeline::load_and_check_scene(scene_file, overrides);
    std::cout << scene_file << ": valid (" << scene.sections().size() << " sections)\n";
  } else if (*run) {
    const auto scene = organfit::pipeline::load_and_check_scene(scene_file, overrides);
    organfit::set_wall_budget(scene.number("scene", "max_wall_s"), "scene.max_wall_s");
    organfit::pipeline::run_scene(scene, out_dir, run_options);
    spdlog::info("done: {}/run.json", out_dir);
  } else if (*bench_stability) {
    const auto summary = organfit::pipeline::run_stability_benchmark(stb);
    std::cout << summary.dump() << "\n";
    if (!summary["all_pass"].get<bool>()) return static_cast<int>(ExitCode::kTargetNotMet);
  } else if (*bench_fit) {
    std::cout << organfit::pipeline::run_fit_benchmark(fb).dump() << "\n";
  } else if (*bench_scale) {
    std::cout << organfit::pipeline::run_scale_benchmark(scb).dump() << "\n";
  } else if (*bench_us) {
    std::cout << organfit::pipeline::run_us_benchmark(usb).dump() << "\n";
  } else if (*bench_ct) {
    std::cout << organfit::pipeline::run_ct_benchmark(ctb).dump() << "\n";
  } else if (*bench_skeleton) {
    std::cout << organfit::evaluation::run_skeleton_benchmark(sb).dump() << "\n";
  } else if (*bench_cohesion) {
    if (scaling) {
      std::cout << organfit::evaluation::run_cohesion_scaling(cb.threads).dump() << "\n";
    } else {
      cb.run_lammps = !no_lammps;
      std::cout << organfit::evaluation::run_cohesion_benchmark(cb).dump() << "\n";
    }
  }
  return 0;
}

}  // namespace

/// An error as one line: control characters (a library's newlines) as spaces, at most
/// 2,000 characters.
std::string one_line(const char* what) {
  std::string s(what);
  for (auto& c : s)
    if (static_cast<unsigned char>(c) < 0x20) c = ' ';
  return s.size() > 2000 ? s.substr(0, 2000) + "..." : s;
}

int main(int argc, char** argv) {
  int code = 0;
  try {
    code = run_main(argc, argv);
    organfit::mark_finishing();
  } catch (const organfit::Error& e) {
    organfit::mark_finishing();
    std::cerr << "organfit: error: " << one_line(e.what()) << "\n";
    code = static_cast<int>(e.code());
  } catch (const std::invalid_argument& e) {  // a force term or integrator refused its input
    organfit::mark_finishing();
    std::cerr << "organfit: error: " << one_line(e.what()) << "\n";
    code = static_cast<int>(ExitCode::kBadInput);
  } catch (const std::exception& e) {
    organfit::mark_finishing();
    std::cerr << "organfit: internal error: " << one_line(e.what()) << "\n";
    code = static_cast<int>(ExitCode::kInternal);
  }
  return code;
}
