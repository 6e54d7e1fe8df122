#include "organfit/support/resources.h"

#include <sys/resource.h>

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

double peak_memory_mib() {
  rusage usage{};
  getrusage(RUSAGE_SELF, &usage);
  return static_cast<double>(usage.ru_maxrss) / 1024.0;  // Linux: ru_maxrss in KiB
}

}  // namespace organfit
