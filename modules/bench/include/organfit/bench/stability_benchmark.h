#pragma once
// `organfit bench stability`: the stiff and extreme cases, each run as a scene for both
// fitting methods: exponents (20, 40); the time step at and beyond its limit; points ten
// organ sizes away, deep inside, on a particle centre, duplicated; 1 and 10,000 points;
// tiny and huge particle radii. Each row says how the run ended (converged, stopped with
// its reason (exit 3), or refused with its reason (exit 2)) and, when it produced a model,
// whether its positions are finite, it is one piece, its kinetic energy stayed bounded and
// how its volume changed. A row passes when the run ended in one of those three ways and
// a produced model is finite, in one piece and bounded.
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
