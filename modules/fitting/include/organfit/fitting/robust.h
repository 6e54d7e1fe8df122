#pragma once
// Outlier rules used in fitting.
//  - outlier_cutoff: values beyond median + k * 1.4826 * MAD are outliers (1.4826 MAD
//    estimates the standard deviation of normally distributed data).
//  - normalised_median_test: a value is an outlier when it disagrees with its spatial
//    neighbours' median by more than `threshold` times their own scatter about it
//    (Westerweel and Scarano, Exp. Fluids 39, 2005, the PIV vector test) and no two of
//    them agree with it.
#include <Eigen/Core>
#include <vector>

namespace organfit::fitting {

/// median(values) + mads * 1.4826 * MAD(values), with the MAD floored at `min_mad` so
/// that identical values do not reject everything else. Empty input: +infinity.
double outlier_cutoff(std::vector<double> values, double mads, double min_mad = 1e-6);

/// The `k` nearest other points of each point (mm; ties by index), nearest first; fewer
/// when there are fewer other points. Bucketed on a grid of about two points a cell.
std::vector<std::vector<int>> k_nearest(const std::vector<Eigen::Vector3d>& points, int k);

/// Normalised median test: value i is an outlier when
///     |v_i - m_i| > threshold (s_i + epsilon),
/// m_i the median of its neighbours' values and s_i the median of |v_j - m_i| over them,
/// unless at least `min_support` (>= 1) neighbours agree with it to within that tolerance
/// (the edge of a group of points that moved together is not an outlier: its own group
/// supports it). Neighbours whose `use` is false are left out, and so is the test for a
/// point with fewer than 3 neighbours left (returned as not an outlier). epsilon (same
/// unit as the values, > 0) is the measurement noise below which disagreement means
/// nothing.
std::vector<char> normalised_median_test(const std::vector<double>& values,
                                         const std::vector<std::vector<int>>& neighbours,
                                         const std::vector<char>& use, double threshold,
                                         double epsilon, int min_support = 2);

}  // namespace organfit::fitting
