#include "organfit/fitting/robust.h"

#include <algorithm>
#include <cmath>
#include <limits>

namespace organfit::fitting {

double outlier_cutoff(std::vector<double> values, double mads, double min_mad) {
  if (values.empty()) return std::numeric_limits<double>::infinity();
  const size_t mid = values.size() / 2;
  std::nth_element(values.begin(), values.begin() + mid, values.end());
  const double median = values[mid];
  for (double& v : values)
    v = std::abs(v - median);
  std::nth_element(values.begin(), values.begin() + mid, values.end());
  return median + mads * 1.4826 * std::max(values[mid], min_mad);
}

}  // namespace organfit::fitting
