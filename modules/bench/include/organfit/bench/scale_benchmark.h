#pragma once
// `organfit bench scale`: organs of several sizes through the planning run (read, organ,
// fill, relax, skeleton, model file) and the session run (load the model, points, fit,
// truth, export, report), each run a separate `organfit run` process so that its peak
// memory is its own. Reports every stage's wall time (s) and the run's peak memory
// (MiB) after it, the particles, and particle-steps per second of the relaxation and of
// the fit; checks the 2.3 L lung and the 1M body against issue 26's targets, and the
// fit step's cost per particle-step for flatness across the sizes run together.
#include <filesystem>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

namespace organfit::bench {

struct ScaleBenchOptions {
  std::filesystem::path out;  ///< a new folder: one sub-folder per case (scenes and runs)
  /// prostate (phantom, 35 cm3), gtv (ct-sts-004, 296 cm3; skipped without
  /// ../shared/data), lung (phantom, 2.3 L at radius 2 mm), million (the same lung at
  /// radius 0.75 mm, about 1M particles, with 87 and 10,000 points). Empty: all.
  std::vector<std::string> cases;
  int threads = 0;  ///< OpenMP threads of each run (0: all cores)
};

/// Issue 26's flatness of the fit step: for each session of the `cases` (scale.json's
/// rows) of at least `from_particles` particles, its cost per particle-step (us, the fit's
/// dynamics steps over the particles they moved), and the largest over the smallest
/// against kFlatLimit. Null when fewer than two sessions qualify.
inline constexpr double kFlatLimit = 1.3;
nlohmann::json fit_step_flatness(const nlohmann::json& cases, double from_particles);

/// Runs the cases; returns machine-readable results. Throws InputError on an unknown
/// case or an output folder that cannot be used, Error when a run fails.
nlohmann::json run_scale_benchmark(const ScaleBenchOptions& options);

}  // namespace organfit::bench
