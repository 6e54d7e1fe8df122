#include "organfit/support/resources.h"

#include <sys/resource.h>

namespace organfit {

double peak_memory_mib() {
  rusage usage{};
  getrusage(RUSAGE_SELF, &usage);
  return static_cast<double>(usage.ru_maxrss) / 1024.0;  // Linux: ru_maxrss in KiB
}

}  // namespace organfit
