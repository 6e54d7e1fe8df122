#pragma once
// The outlier rule used throughout fitting: values beyond median + k * 1.4826 * MAD are
// outliers (1.4826 MAD estimates the standard deviation of normally distributed data).
#include <vector>

namespace organfit::fitting {

/// median(values) + mads * 1.4826 * MAD(values), with the MAD floored at `min_mad` so
/// that identical values do not reject everything else. Empty input: +infinity.
double outlier_cutoff(std::vector<double> values, double mads, double min_mad = 1e-6);

}  // namespace organfit::fitting
