#pragma once
// Wall time and memory of a stage, as reported in run.json.
#include <chrono>

namespace organfit {

/// Peak resident memory of this process so far, in MiB (getrusage).
double peak_memory_mib();

/// Wall-clock stopwatch in seconds.
class Stopwatch {
 public:
  Stopwatch() : start_(std::chrono::steady_clock::now()) {}
  double elapsed_s() const {
    return std::chrono::duration<double>(std::chrono::steady_clock::now() - start_).count();
  }
  void restart() { start_ = std::chrono::steady_clock::now(); }

 private:
  std::chrono::steady_clock::time_point start_;
};

}  // namespace organfit
