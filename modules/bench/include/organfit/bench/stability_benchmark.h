#pragma once
// `organfit bench stability`: the stiff and extreme cases, each through the model, points
// and fit stages (library calls, no scene) for both fitting methods: exponents (20, 40); the
// time step at and beyond its limit; points ten organ sizes away, deep inside, on a particle
// centre, duplicated; 1 and 10,000 points; tiny and huge particle radii. Each row says how
// the case ended (converged; stopped with its reason, where `organfit run` exits 3; or
// refused with its reason, exit 2) and, when it produced a model, whether its positions are
// finite, it is one piece, its kinetic energy stayed bounded and how its volume changed. A
// row passes when the case ended in one of those three ways and a produced model is finite,
// in one piece and bounded.
#include <filesystem>
#include <nlohmann/json.hpp>

namespace organfit::bench {

struct StabilityBenchOptions {
  std::filesystem::path out;
  int threads = 0;
};

/// Writes DIR/stability.csv and DIR/STABILITY.md; returns the summary (all_pass).
nlohmann::json run_stability_benchmark(const StabilityBenchOptions& options);

}  // namespace organfit::bench
