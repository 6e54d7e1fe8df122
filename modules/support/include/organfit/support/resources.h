#pragma once
// Wall time and memory of a stage, as reported in run.json.
#include <chrono>

namespace organfit {

/// Keeps the memory this process frees for its own later allocations rather than giving it
/// back to the kernel (glibc: no separate mapping per large block, no trimming of the
/// heap's top). A run allocates and frees grids of 10 to 300 MB many times (distance
/// transforms, the deformation's lattice, the truth's bodies); each fresh mapping is
/// zeroed by the kernel page by page, 7% of a million-particle session's cycles. The peak
/// stays about the same (what was freed is reused); the process holds it until it exits.
/// Call once, first thing in main(). No effect with another C library.
void keep_freed_memory();

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
