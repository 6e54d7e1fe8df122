#pragma once
// Bounds on sums over a row of unit Gaussian bumps one sigma apart, for the shear fields'
// bounds (global_map.cpp) and their table's error (shear_field_table.cpp).
#include <array>

namespace organfit::fitting::detail {

/// sup over x of sum_i |g^(m)(x - i)|, g(t) = exp(-t^2 / 2), for m = 0 .. 4: [0] sum g,
/// [1] sum |t| g, [2] sum |t^2 - 1| g, [3] sum |t^3 - 3t| g, [4] sum |t^4 - 6t^2 + 3| g.
/// Sampled over a period at 1/1000 and raised by 0.01, more than the sampling can miss
/// (the sums' slopes are below 10).
const std::array<double, 5>& bump_sum_bounds();

}  // namespace organfit::fitting::detail
