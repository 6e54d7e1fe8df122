#pragma once
// Wall time and memory of a stage, as reported in run.json.
#include <chrono>
#include <optional>
#include <string>

namespace organfit {

/// Keeps the memory this process frees for its own later allocations rather than giving it
/// back to the kernel (glibc: no separate mapping per large block, no trimming of the
/// heap's top). A run allocates and frees grids of 10 to 300 MB many times (distance
/// transforms, the deformation's lattice, the truth's bodies); each fresh mapping is
/// zeroed by the kernel page by page, 7% of a million-particle session's cycles. The peak
/// stays about the same (what was freed is reused); the process holds it until it exits.
/// Call once, first thing in main(). No effect with another C library.
void keep_freed_memory();

/// Starts the program again, once (same process, same arguments), with what the C library
/// and the OpenMP runtime read only when a program starts, where either is to be set:
/// - huge pages (huge_page_tunables): glibc's malloc asks for transparent huge pages (2 MiB)
///   where the kernel gives them only on request (`/sys/kernel/mm/transparent_hugepage/
///   enabled` is "madvise", as on the machine the benchmarks ran on). A run touches 60 to
///   4,000 MB once, and with 4 KiB pages each first touch is a page fault (51,000 in a 2.2 L
///   lung's session; in a virtual machine a fault costs microseconds: 0.27 s of its 2.2 s);
/// - the OpenMP threads' busy wait (openmp_spin_count): how long a thread waiting at a
///   barrier spins before it sleeps. libgomp spins 300,000 times by default, about a
///   millisecond, burning the core the thread it waits for may need: on a machine where
///   other programs run, half of a session's cycles went to spinning and it took twice as
///   long (docs/decisions.md).
/// It returns when nothing is to be done (another C library, both answered already, a
/// set-user-ID start, where the settings are dropped and asking again would never end) or
/// when the exec fails (the variables it set are put back). Call first thing in main(),
/// before any thread or file is opened.
void start_with_runtime_settings(char** argv);
/// The GLIBC_TUNABLES value to start again with, given the present one (null: unset) and
/// the kernel's mode line ("always [madvise] never"); nullopt when there is nothing to ask
/// (another mode, or glibc.malloc.hugetlb already named: =0 declines it).
std::optional<std::string> huge_page_tunables(const char* present, const std::string& thp_mode);
/// The GOMP_SPINCOUNT value to start again with, given OMP_WAIT_POLICY's and
/// GOMP_SPINCOUNT's present values (null: unset): 10,000 spins (10 to 30 us, about what a
/// sleeping thread takes to wake: spinning longer cannot pay for itself), or nullopt when
/// either is set (the user's choice, or the run that started this one).
std::optional<std::string> openmp_spin_count(const char* wait_policy, const char* spin_count);

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
