#pragma once
// `organfit bench ct`: the CT stage's cost on a clinical-size CT: read the DICOM series,
// grow the organ from a seed, build its skeleton and fill it with particles, with the
// wall time of each step and the process's peak memory.
#include <filesystem>
#include <nlohmann/json.hpp>
#include <vector>

namespace organfit::bench {

struct CtBenchOptions {
  /// A CT folder; empty: a pelvis phantom of columns x rows x slices is made first by a
  /// separate `organfit synth pelvis` process (so its memory is not counted).
  std::filesystem::path ct;
  int columns = 512, rows = 512, slices = 100;
  std::vector<double> seed_mm{0, 0, 0};   ///< organ seed (default: the phantom's prostate)
  std::vector<double> hu_window{20, 80};  ///< organ HU window
  double radius_mm = 1.5;                 ///< particle radius
  int threads = 0;                        ///< 0: all cores
  double target_s = 10.0;  ///< the issue's budget for read + segment + skeleton + seed
};

/// Runs the benchmark; returns machine-readable results (timings in s, memory in MiB).
nlohmann::json run_ct_benchmark(const CtBenchOptions& options);

}  // namespace organfit::bench
