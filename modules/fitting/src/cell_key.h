#pragma once
// Hash key of a cell of a uniform grid (the fitting module's bucketed neighbour
// searches): 21 bits per axis, cells within +-2^20 of the grid's origin (callers bound
// them).
#include <Eigen/Core>

namespace organfit::fitting {

inline long long cell_key(const Eigen::Vector3i& c) {
  return (static_cast<long long>(c.x() + (1 << 20)) << 42) |
         (static_cast<long long>(c.y() + (1 << 20)) << 21) |
         static_cast<long long>(c.z() + (1 << 20));
}

}  // namespace organfit::fitting
