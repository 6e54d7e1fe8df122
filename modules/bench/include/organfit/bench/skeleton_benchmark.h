#pragma once
// `organfit bench skeleton`: does the skeleton keep an elongated body's shape in a
// fluid-like state, and does the body round up without it?
//
// An ellipsoid (default 60 x 25 x 25 mm, r0 = 2 mm, LJ 12-6) is filled, relaxed, then
// run under a Langevin thermostat hot enough to melt the LJ solid, once with the
// skeleton and once without, from the same state and noise. Reported for both: aspect
// ratio (largest / smallest principal extent) before and after, and the mean surface
// distance of the body to its start after rigid alignment (geometry/mask_ops.h).
#include <nlohmann/json.hpp>

namespace organfit::bench {

struct SkeletonBenchOptions {
  double size_x_mm = 60, size_yz_mm = 25;
  double r0_mm = 2.0;
  double temperature = 0.7;  ///< kT in units of E0 (this truncated LJ melts near 0.62-0.69)
  double friction = 0.5;     ///< thermostat friction K_a / M (1/s)
  long long steps = 20000;
  double stiffness_fraction =
      0.2;                       ///< skeleton k_s as a fraction of the LJ stiffness m n E0 / r0^2
  double node_spacing_r0 = 3.0;  ///< distance between skeleton nodes, in r0
  double overlap_r0 = 0.5;       ///< cluster overlap, in r0
  int threads = 1;
};

nlohmann::json run_skeleton_benchmark(const SkeletonBenchOptions& options);

}  // namespace organfit::bench
