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

/// Asks glibc's malloc for transparent huge pages (2 MiB) where the kernel gives them only
/// on request (`/sys/kernel/mm/transparent_hugepage/enabled` is "madvise", as on the machine
/// the benchmarks ran on): a run touches 60 to 4,000 MB once, and with 4 KiB pages
/// each first touch is a page fault (51,000 in a 2.2 L lung's session; in a virtual machine
/// a fault costs microseconds: 0.27 s of its 2.2 s). glibc reads the request
/// (GLIBC_TUNABLES=glibc.malloc.hugetlb=1) only when a program starts, so this re-executes
/// the program with it set, once (same process, same arguments); it returns when nothing
/// is to be done: another C library or kernel mode, GLIBC_TUNABLES already naming
/// glibc.malloc.hugetlb (=0 declines it), a set-user-ID start (glibc drops the request
/// there, and asking again would never end), or an exec that fails. Call first thing in
/// main(), before any thread or file is opened.
void request_huge_pages(char** argv);
/// request_huge_pages' decision: the GLIBC_TUNABLES value to start again with, given the
/// present one (null: unset) and the kernel's mode line ("always [madvise] never");
/// nullopt when there is nothing to ask.
std::optional<std::string> huge_page_tunables(const char* present, const std::string& thp_mode);

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
