#pragma once
// The Z-order (Morton) code of a cell of a 3D grid: the bits of x, y and z interleaved
// (x lowest). Cells near in space get codes near in value at every scale, so sorting by the
// code puts near things near in memory.
#include <cstdint>

namespace organfit::geometry {

/// Code of cell (x, y, z), each coordinate's low 21 bits (cells 0 to 2,097,151 per axis).
inline std::uint64_t morton_code(std::uint64_t x, std::uint64_t y, std::uint64_t z) {
  auto spread = [](std::uint64_t v) {  // the bits of v at every third place
    v &= 0x1fffff;
    v = (v | v << 32) & 0x1f00000000ffffULL;
    v = (v | v << 16) & 0x1f0000ff0000ffULL;
    v = (v | v << 8) & 0x100f00f00f00f00fULL;
    v = (v | v << 4) & 0x10c30c30c30c30c3ULL;
    v = (v | v << 2) & 0x1249249249249249ULL;
    return v;
  };
  return spread(x) | spread(y) << 1 | spread(z) << 2;
}

}  // namespace organfit::geometry
