#include "organfit/support/resources.h"

#include <sys/resource.h>
#include <unistd.h>

#if defined(__linux__)
#include <sys/auxv.h>
#endif

#include <cstdlib>
#include <fstream>
#include <string>

#if defined(__GLIBC__)
#include <malloc.h>
#endif

namespace organfit {

void keep_freed_memory() {
#if defined(__GLIBC__)
  mallopt(M_MMAP_MAX, 0);         // large blocks from the heap, reused once freed
  mallopt(M_TRIM_THRESHOLD, -1);  // the heap's free top kept (-1: never trimmed)
#endif
}

std::optional<std::string> huge_page_tunables(const char* present, const std::string& thp_mode) {
  const std::string tunables = present ? present : "";
  if (tunables.find("glibc.malloc.hugetlb") != std::string::npos) return std::nullopt;
  if (thp_mode.find("[madvise]") == std::string::npos) return std::nullopt;  // always, never
  return tunables + (tunables.empty() ? "" : ":") + "glibc.malloc.hugetlb=1";
}

void request_huge_pages(char** argv) {
#if defined(__GLIBC__) && defined(__linux__)
  if (getauxval(AT_SECURE) != 0) return;
  const char* present = std::getenv("GLIBC_TUNABLES");
  std::ifstream mode_file("/sys/kernel/mm/transparent_hugepage/enabled");
  std::string mode;
  std::getline(mode_file, mode);
  const std::optional<std::string> tunables = huge_page_tunables(present, mode);
  if (!tunables) return;
  const std::string kept = present ? present : "";
  if (setenv("GLIBC_TUNABLES", tunables->c_str(), 1) != 0) return;
  execv("/proc/self/exe", argv);
  // The exec failed (no /proc): run on with the pages as they are, and no request left set
  // for programs this one starts.
  if (present) {
    setenv("GLIBC_TUNABLES", kept.c_str(), 1);
  } else {
    unsetenv("GLIBC_TUNABLES");
  }
#else
  (void)argv;
#endif
}

double peak_memory_mib() {
  rusage usage{};
  getrusage(RUSAGE_SELF, &usage);
  return static_cast<double>(usage.ru_maxrss) / 1024.0;  // Linux: ru_maxrss in KiB
}

}  // namespace organfit
