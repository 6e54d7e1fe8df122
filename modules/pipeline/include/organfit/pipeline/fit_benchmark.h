#pragma once
// `organfit bench fit`: error against run time on known deformations, the particle fit
// (the paper's method and ours) side by side with thin-plate-spline, coherent-point-drift
// and similarity-ICP baselines on the same points (METHOD.md s.7).
//
// Each case: an organ shape, a volume-preserving deformation family and magnitude (the
// largest displacement it causes, mm), points on the posterior half of the deformed
// surface (what a transrectal probe sees) with noise and outliers, seeded. Every method's
// result is the model's particles moved (by the fit, or by the baseline's map), measured
// the same way (geometry/mask_ops.h):
//   msd_mm     symmetric mean surface distance between the particles' closed body (balls
//              of rho closed by rho) and the true deformed body, on a grid of rho/2;
//   hd95_mm    the symmetric 95th percentile of the same surface distances;
//   dice       on that grid;
//   volume_change_pct  the closed body's volume against the model's before the fit;
//   residual_mm  mean over the points of |distance to the nearest particle centre - rho|.
// Writes DIR/results.csv, DIR/curves.csv (the particle fits' histories), DIR/work_precision.svg
// and DIR/RESULTS.md.
#include <filesystem>
#include <nlohmann/json.hpp>

namespace organfit::pipeline {

struct FitBenchOptions {
  std::filesystem::path out;
  bool quick = false;  ///< 2 shapes x 5 families x 2 magnitudes, 87 points, 0.5 mm noise
  int threads = 0;
};

nlohmann::json run_fit_benchmark(const FitBenchOptions& options);

}  // namespace organfit::pipeline
