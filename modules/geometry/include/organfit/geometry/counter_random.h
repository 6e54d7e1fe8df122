#pragma once
// Counter-based random numbers: a value from a key alone (splitmix64), so that noise or a
// sample's jitter is fixed by what it belongs to (a voxel, a step and a particle), whatever
// the thread count or order.
#include <cstdint>

namespace organfit::geometry {

/// splitmix64's output function: a bijective mix of the 64 bits of `z`.
inline std::uint64_t splitmix64(std::uint64_t z) {
  z += 0x9e3779b97f4a7c15ULL;
  z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ULL;
  z = (z ^ (z >> 27)) * 0x94d049bb133111ebULL;
  return z ^ (z >> 31);
}

/// A uniform deviate in (0, 1) from `key`.
inline double uniform01(std::uint64_t key) {
  return (static_cast<double>(splitmix64(key) >> 11) + 0.5) * 0x1.0p-53;
}

}  // namespace organfit::geometry
