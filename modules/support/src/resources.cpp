#include "organfit/support/resources.h"

#include <sys/resource.h>
#include <unistd.h>

#if defined(__linux__)
#include <sys/auxv.h>
#endif

#include <cstdlib>
#include <fstream>
#include <string>
#include <vector>

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

std::optional<std::string> openmp_spin_count(const char* wait_policy, const char* spin_count) {
  if (wait_policy || spin_count) return std::nullopt;
  return "10000";
}

void start_with_runtime_settings(char** argv) {
#if defined(__GLIBC__) && defined(__linux__)
  if (getauxval(AT_SECURE) != 0) return;
  std::ifstream mode_file("/sys/kernel/mm/transparent_hugepage/enabled");
  std::string mode;
  std::getline(mode_file, mode);
  // Each variable to set, with its present value (nullopt: unset) to put back if the exec fails.
  struct Change {
    const char* name;
    std::string value;
    std::optional<std::string> before;
  };
  std::vector<Change> changes;
  auto present = [](const char* name) -> std::optional<std::string> {
    const char* value = std::getenv(name);
    return value ? std::optional<std::string>(value) : std::nullopt;
  };
  if (const auto tunables = huge_page_tunables(std::getenv("GLIBC_TUNABLES"), mode))
    changes.push_back({"GLIBC_TUNABLES", *tunables, present("GLIBC_TUNABLES")});
  if (const auto spins =
          openmp_spin_count(std::getenv("OMP_WAIT_POLICY"), std::getenv("GOMP_SPINCOUNT")))
    changes.push_back({"GOMP_SPINCOUNT", *spins, std::nullopt});
  if (changes.empty()) return;
  bool all_set = true;
  for (const Change& c : changes)
    all_set = all_set && setenv(c.name, c.value.c_str(), 1) == 0;
  if (all_set) execv("/proc/self/exe", argv);
  // A variable not set, or the exec failed (no /proc): run on as things are, and nothing
  // left set for programs this one starts.
  for (const Change& c : changes) {
    if (c.before) {
      setenv(c.name, c.before->c_str(), 1);
    } else {
      unsetenv(c.name);
    }
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
