// `organfit bench cohesion|skeleton|ct|us|fit|scale|stability`: the benchmarks
// (modules/bench), each printing machine-readable JSON on stdout.
#include <iostream>
#include <memory>

#include "commands.h"
#include "organfit/bench/cohesion_benchmark.h"
#include "organfit/bench/ct_benchmark.h"
#include "organfit/bench/fit_benchmark.h"
#include "organfit/bench/scale_benchmark.h"
#include "organfit/bench/skeleton_benchmark.h"
#include "organfit/bench/stability_benchmark.h"
#include "organfit/bench/us_benchmark.h"
#include "organfit/support/error.h"

namespace organfit::app {

std::vector<Command> add_bench(CLI::App& app) {
  struct Options {
    bench::CohesionBenchOptions cb;
    bench::SkeletonBenchOptions sb;
    bench::CtBenchOptions ctb;
    bench::UsBenchOptions usb;
    bench::FitBenchOptions fb;
    bench::ScaleBenchOptions scb;
    bench::StabilityBenchOptions stb;
    bool scaling = false, no_lammps = false;
  };
  auto o = std::make_shared<Options>();
  auto* bench = app.add_subcommand("bench", "Benchmarks; print machine-readable JSON on stdout");
  bench->require_subcommand(1);
  auto* bench_cohesion = bench->add_subcommand(
      "cohesion", "LJ cohesion on the LAMMPS in.lj system, side by side with LAMMPS");
  bench_cohesion->add_option("--particles", o->cb.particles, "Particle count (whole fcc cells)")
      ->check(CLI::Range(4LL, 50000000LL));
  bench_cohesion->add_option("--steps", o->cb.steps, "Steps")->check(CLI::Range(1LL, 1000000LL));
  bench_cohesion->add_option("--threads", o->cb.threads, "OpenMP threads")
      ->check(CLI::Range(1, 256));
  bench_cohesion->add_flag("--scaling", o->scaling,
                           "Cost per particle-step from 1e3 to 1e6 particles");
  bench_cohesion->add_flag("--no-lammps", o->no_lammps, "Do not run LAMMPS alongside");

  auto* bench_skeleton = bench->add_subcommand(
      "skeleton", "Shape kept with the skeleton vs rounding up without, in a fluid-like state");
  bench_skeleton->add_option("--steps", o->sb.steps, "Thermostat steps")
      ->check(CLI::Range(1LL, 100000000LL));
  bench_skeleton->add_option("--temperature", o->sb.temperature, "kT in units of E0")
      ->check(CLI::Range(0.0, 10.0));
  bench_skeleton->add_option("--friction", o->sb.friction, "Thermostat friction K_a/M (1/s)")
      ->check(CLI::PositiveNumber);
  bench_skeleton
      ->add_option("--stiffness", o->sb.stiffness_fraction, "Skeleton stiffness / LJ stiffness")
      ->check(CLI::PositiveNumber);
  bench_skeleton->add_option("--node-spacing", o->sb.node_spacing_r0, "Skeleton node spacing (r0)")
      ->check(CLI::PositiveNumber);
  bench_skeleton->add_option("--length", o->sb.size_x_mm, "Ellipsoid length (mm)")
      ->check(CLI::PositiveNumber);
  bench_skeleton->add_option("--width", o->sb.size_yz_mm, "Ellipsoid width (mm)")
      ->check(CLI::PositiveNumber);
  bench_skeleton->add_option("--threads", o->sb.threads, "OpenMP threads")
      ->check(CLI::Range(1, 256));

  auto* bench_ct = bench->add_subcommand(
      "ct", "CT stage on a 512x512x100 CT: read + segment + skeleton + seed, with peak memory");
  bench_ct->add_option("--ct", o->ctb.ct, "CT folder (default: a pelvis phantom made first)");
  bench_ct->add_option("--columns", o->ctb.columns, "Phantom columns")->check(CLI::Range(64, 2048));
  bench_ct->add_option("--rows", o->ctb.rows, "Phantom rows")->check(CLI::Range(64, 2048));
  bench_ct->add_option("--slices", o->ctb.slices, "Phantom slices")->check(CLI::Range(8, 2000));
  bench_ct->add_option("--seed", o->ctb.seed_mm, "Organ seed X,Y,Z (mm)")
      ->delimiter(',')
      ->expected(3);
  bench_ct->add_option("--hu", o->ctb.hu_window, "Organ HU window LO,HI")
      ->delimiter(',')
      ->expected(2);
  bench_ct->add_option("--radius", o->ctb.radius_mm, "Particle radius (mm)")
      ->check(CLI::Range(0.3, 20.0));
  bench_ct->add_option("--threads", o->ctb.threads, "OpenMP threads (0: all)")
      ->check(CLI::Range(0, 256));

  auto* bench_us =
      bench->add_subcommand("us", "Ultrasound segmentation: a 256^3 volume and a 100-frame sweep");
  bench_us->add_option("--size", o->usb.volume_size, "Volume voxels per side")
      ->check(CLI::Range(32, 1024));
  bench_us->add_option("--frames", o->usb.frames, "Sweep frames")->check(CLI::Range(1, 10000));
  bench_us->add_option("--threads", o->usb.threads, "OpenMP threads (0: all)")
      ->check(CLI::Range(0, 256));

  auto* bench_fit = bench->add_subcommand(
      "fit", "Error against run time: the particle fits and TPS, CPD, ICP on known deformations");
  bench_fit
      ->add_option("-o,--out", o->fb.out,
                   "Output folder: results.csv, curves.csv, work_precision.svg, RESULTS.md")
      ->required();
  bench_fit->add_flag("--quick", o->fb.quick,
                      "The quick grid (20 cases, a few minutes on 2 cores)");
  bench_fit->add_flag("--fem", o->fb.fem,
                      "The biomechanical ground truth: the prostate and real GTVs deformed by a "
                      "FEM engine (GetFEM) under a probe and bladder filling, 2 to 12 mm (24 "
                      "cases; solved once, then cached)");
  bench_fit->add_option("--fem-cache", o->fb.fem_cache,
                        "Folder of the FEM cases (default $ORGANFIT_FEM_CACHE, else "
                        "~/.cache/organfit/fem)");
  bench_fit->add_flag("--sessions", o->fb.sessions,
                      "The regime of treatment sessions: rigid shifts and rotations and every "
                      "family at 0 to 5 mm (70 cases), with do-no-harm counts");
  bench_fit->add_option("--threads", o->fb.threads, "OpenMP threads (0: all)")
      ->check(CLI::Range(0, 256));
  bench_fit
      ->add_option("--sample", o->fb.sample,
                   "Run N cases, a seeded uniform sample of the grid (0: all)")
      ->check(CLI::Range(0LL, 1000000LL));
  bench_fit->add_flag("--targets", o->fb.targets,
                      "Only the cases the targets name (<= 87 points, 0.5 mm noise, no outliers, "
                      "<= 10 mm): 225 of the grid's 2,400");
  bench_fit
      ->add_option("--cases", o->fb.cases,
                   "Only these cases, comma-separated, by their number in the grid (results.csv's "
                   "case column)")
      ->delimiter(',');
  bench_fit
      ->add_option(
          "--methods", o->fb.methods,
          "Only these methods, comma-separated: spread, paper, tps, cpd, icp (default: all)")
      ->delimiter(',');
  bench_fit->add_flag("--defaults-only", o->fb.defaults_only,
                      "Each method at its default setting only (the same results.csv rows; no "
                      "work-precision settings besides)");

  auto* bench_scale = bench->add_subcommand(
      "scale", "Organs from 35 cm3 to 2.3 L and 1M particles: each stage's time and memory");
  bench_scale->add_option("-o,--out", o->scb.out, "Output folder (new): scenes, runs, scale.json")
      ->required();
  bench_scale
      ->add_option(
          "--cases", o->scb.cases,
          "Only these, comma-separated: prostate, gtv, lung, liver, million (default: all)")
      ->delimiter(',');
  bench_scale->add_option("--threads", o->scb.threads, "OpenMP threads of each run (0: all)")
      ->check(CLI::Range(0, 256));

  auto* bench_stability = bench->add_subcommand(
      "stability", "Stiff and extreme cases, both fitting methods: a pass/fail table");
  bench_stability->add_option("-o,--out", o->stb.out, "Output folder: stability.csv, STABILITY.md")
      ->required();
  bench_stability->add_option("--threads", o->stb.threads, "OpenMP threads (0: all)")
      ->check(CLI::Range(0, 256));

  auto print = [](const nlohmann::json& summary) {
    std::cout << summary.dump() << "\n";
    return 0;
  };
  return {{bench_cohesion,
           [o, print] {
             if (o->scaling) return print(bench::run_cohesion_scaling(o->cb.threads));
             o->cb.run_lammps = !o->no_lammps;
             return print(bench::run_cohesion_benchmark(o->cb));
           }},
          {bench_skeleton, [o, print] { return print(bench::run_skeleton_benchmark(o->sb)); }},
          {bench_ct, [o, print] { return print(bench::run_ct_benchmark(o->ctb)); }},
          {bench_us, [o, print] { return print(bench::run_us_benchmark(o->usb)); }},
          {bench_fit, [o, print] { return print(bench::run_fit_benchmark(o->fb)); }},
          {bench_scale, [o, print] { return print(bench::run_scale_benchmark(o->scb)); }},
          {bench_stability, [o, print] {
             const auto summary = bench::run_stability_benchmark(o->stb);
             print(summary);
             return summary["all_pass"].get<bool>() ? 0 : static_cast<int>(ExitCode::kTargetNotMet);
           }}};
}

}  // namespace organfit::app
