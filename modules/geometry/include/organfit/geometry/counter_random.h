#pragma once
// Counter-based random numbers: a value from a key alone (splitmix64), so that noise or a
// sample's jitter is fixed by what it belongs to (a voxel, a step and a particle), whatever
// the thread count or order.
#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <cstring>

namespace organfit::geometry {

/// splitmix64's output function: a bijective mix of the 64 bits of `z`.
inline std::uint64_t splitmix64(std::uint64_t z) {
  z += 0x9e3779b97f4a7c15ULL;
  z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ULL;
  z = (z ^ (z >> 27)) * 0x94d049bb133111ebULL;
  return z ^ (z >> 31);
}

/// `bytes` bytes at `data` folded into the hash `h`, 8 at a time through splitmix64 (the
/// last word zero-padded, the length folded last): a fingerprint of content, to notice a
/// change, not a defence against one made on purpose.
inline std::uint64_t hash_bytes(std::uint64_t h, const void* data, std::size_t bytes) {
  const auto* p = static_cast<const unsigned char*>(data);
  for (std::size_t at = 0; at < bytes; at += 8) {
    std::uint64_t word = 0;
    std::memcpy(&word, p + at, std::min<std::size_t>(8, bytes - at));
    h = splitmix64(h ^ word);
  }
  return splitmix64(h ^ bytes);
}

/// A uniform deviate in (0, 1) from `key`.
inline double uniform01(std::uint64_t key) {
  return (static_cast<double>(splitmix64(key) >> 11) + 0.5) * 0x1.0p-53;
}

}  // namespace organfit::geometry
