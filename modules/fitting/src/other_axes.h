#pragma once
// The two axes other than one, in order: the plane a shear field of that axis lives in
// (global_map.h, shear_field_table.h) and the edges across a lattice cell's face
// (deformation.cpp).
#include <utility>

namespace organfit::fitting::detail {

/// The two axes other than `a` (0, 1 or 2), the lower first.
inline std::pair<int, int> other_axes(int a) {
  return {a == 0 ? 1 : 0, a == 2 ? 1 : 2};
}

}  // namespace organfit::fitting::detail
