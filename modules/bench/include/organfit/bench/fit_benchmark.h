#pragma once
// `organfit bench fit`: error against run time on known deformations, the particle fit
// (the paper's method and ours) side by side with thin-plate-spline, coherent-point-drift
// and similarity-ICP baselines on the same points (METHOD.md s.7).
//
// Each case: an organ shape, a volume-preserving deformation family and magnitude (the
// largest displacement it causes, mm), points on the posterior half of the deformed
// surface (what a transrectal probe sees) with noise and outliers, seeded. Every method
// moves the model's particles (by the fit, or by the baseline's map), and its result is
// the organ those particles carry: the model's reference body moved with them
// (fitting/embedded_body.h; the particle fits with their global map, the baselines with
// their map sampled at the particles), measured the same way (geometry/mask_ops.h):
//   msd_mm     symmetric mean surface distance between that organ and the true deformed
//              body, both on a grid of 0.5 mm covering both (evaluation::kTruthVoxelMm,
//              whatever the model's resolution): the mean, over the surface voxels of
//              each mask, of the distance to the other mask's surface voxels;
//   hd95_mm    the 95th percentile of the same two sets of distances pooled;
//   dice       on that grid;
//   volume_change_pct  that organ's volume on that grid against the model's reference
//              body (its own voxel count);
//   msd_balls_mm, volume_change_balls_pct  the same for the particles' own body (balls
//              of rho closed by rho), the paper's surface;
//   residual_mm  mean over the points of |distance to the nearest particle centre - rho|;
//   msd_global_mm  (ours only) msd_mm of the organ after the global stage alone (the
//              reference moved by the global map), before the local stage;
//   case       the case's number in the grid (--cases N reruns it alone);
//   global_fit (ours only) which global fit was kept (fitting::GlobalMap::found_by);
//   msd_undeformed_mm  the organ left as it was (the model at rest) against the same truth.
// Families: stretch, bend, twist, indent, push (evaluation::Deformation) and, in the
// session regime, shift (rigid, along (1, -2, 2)/3) and rotate (rigid, about (2, 1, -2)/3
// through the centre, by magnitude / half the largest extent: 0 to 5.2 degrees on the
// prostate up to 2 mm); with --fem, fem_probe and fem_bladder: the organ deformed by a FEM
// engine (pipeline/fem_cases.h), whose own volume change is the row's
// truth_volume_change_pct.
// The particle fits run with the scene defaults except fit.spread.max_global_stretch: 2 (the
// grid stretches a 30 mm cube by up to 2x; the default 1.5 would refuse it) and
// fit.max_wall_s: 20.
// Work precision: each method also runs at other settings of its effort (TPS 1, 2 and
// 10 rounds beside its 5; CPD 15 and 50 iterations beside its 150; ICP 3 and 10 beside
// its 30; ours also after its global stage alone), one row per case, method and setting
// in work_precision.csv (method,effort,case,wall_s,msd_mm); the plot joins each method's
// medians per setting into a curve, and the summary compares ours with TPS and CPD at
// ours' wall time (a baseline's best over the settings that run within it).
// Writes DIR/results.csv, DIR/work_precision.csv, DIR/curves.csv (the particle fits'
// histories), DIR/work_precision.svg and DIR/RESULTS.md.
#include <filesystem>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

namespace organfit::bench {

struct FitBenchOptions {
  std::filesystem::path out;
  /// quick: the phantom's prostate and a 30 mm cube x 5 families x 5 and 10 mm, 87
  /// points, 0.5 mm noise, no outliers (20 cases). Full: also an egg, a lung-like body and
  /// the real GTV of ct-sts-004; 2, 5, 10, 15 mm; 20, 50, 87, 200 points; 0, 0.5, 1 mm
  /// noise; 0 and 5% outliers.
  bool quick = false;
  /// the regime of treatment sessions instead: the phantom's prostate and the 30 mm cube x
  /// a rigid shift, a rigid rotation and the 5 families x 0, 0.5, 1, 2, 5 mm, 87 points,
  /// 0.5 mm noise (70 cases); the summary counts the cases that break do-no-harm (an MSD
  /// above the undeformed organ's + 0.1 mm, or above TPS's)
  bool sessions = false;
  /// the biomechanical ground truth instead (pipeline/fem_cases.h): the phantom's prostate
  /// and the real GTVs of ct-sts-004 and ct-sts-002 (when ../shared/data has them) x a
  /// transrectal probe from posterior and bladder filling from superior x 2, 5, 8, 12 mm, 87
  /// points, 0.5 mm noise (24 cases); the FEM runs once per organ and load and is cached
  bool fem = false;
  std::filesystem::path fem_cache;  ///< empty: default_fem_cache()
  long long sample = 0;  ///< run this many cases, a seeded uniform sample of the grid (0: all)
  /// run only these cases, by their number in the grid (results.csv's `case`: the same
  /// case, points and seed as in a whole run); numbers beyond the grid are an InputError,
  /// and so is giving `sample` as well
  std::vector<long long> cases;
  /// run only the cases the targets name (at most 87 points, 0.5 mm noise, no outliers,
  /// at most 10 mm): 225 of the whole grid's 2,400, all of the quick grid
  bool targets = false;
  /// run only these of spread, paper, tps, cpd, icp (empty: all); an unknown name is an
  /// InputError
  std::vector<std::string> methods;
  /// each method at its default setting only: no work-precision settings besides (the
  /// rows of results.csv are the same; work_precision.csv has one setting per method)
  bool defaults_only = false;
  int threads = 0;
};

nlohmann::json run_fit_benchmark(const FitBenchOptions& options);

}  // namespace organfit::bench
