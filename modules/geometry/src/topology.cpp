#include "organfit/geometry/topology.h"

#include <algorithm>
#include <cstdint>
#include <vector>

namespace organfit::geometry {

Topology topology_of(const LabelVolume& mask) {
  const IndexRange box = mask.range(1);
  const std::array<int, 3>&lo = box.lo, &hi = box.hi;
  Topology t;
  if (box.empty()) return t;
  // The box plus a layer of background all round (outside the grid counts as
  // background), so that the outside is one 6-connected piece touching the box's border.
  int n[3];
  for (int d = 0; d < 3; ++d)
    n[d] = hi[d] - lo[d] + 3;
  const long long total = 1LL * n[0] * n[1] * n[2];
  std::vector<std::uint8_t> in(static_cast<size_t>(total), 0);
  for (int k = 1; k + 1 < n[2]; ++k)
    for (int j = 1; j + 1 < n[1]; ++j)
      for (int i = 1; i + 1 < n[0]; ++i)
        in[static_cast<size_t>(i + 1LL * n[0] * (j + 1LL * n[1] * k))] =
            mask.at(lo[0] + i - 1, lo[1] + j - 1, lo[2] + k - 1) == 1;
  std::vector<std::uint8_t> seen(static_cast<size_t>(total), 0);
  std::vector<long long> stack;
  // Flood fill from v over voxels whose `in` is `value`, with 26 or 6 neighbours; returns
  // the piece's size and whether it reaches the box's border.
  auto fill = [&](long long v, std::uint8_t value, bool full) {
    long long size = 0;
    bool border = false;
    stack.assign(1, v);
    seen[static_cast<size_t>(v)] = 1;
    while (!stack.empty()) {
      const long long w = stack.back();
      stack.pop_back();
      ++size;
      const int i = static_cast<int>(w % n[0]), j = static_cast<int>((w / n[0]) % n[1]),
                k = static_cast<int>(w / (1LL * n[0] * n[1]));
      if (i == 0 || j == 0 || k == 0 || i == n[0] - 1 || j == n[1] - 1 || k == n[2] - 1)
        border = true;
      for (int dk = -1; dk <= 1; ++dk)
        for (int dj = -1; dj <= 1; ++dj)
          for (int di = -1; di <= 1; ++di) {
            const int steps = std::abs(di) + std::abs(dj) + std::abs(dk);
            if (steps == 0 || (!full && steps > 1)) continue;
            const int a = i + di, b = j + dj, c = k + dk;
            if (a < 0 || b < 0 || c < 0 || a >= n[0] || b >= n[1] || c >= n[2]) continue;
            const long long u = a + 1LL * n[0] * (b + 1LL * n[1] * c);
            if (seen[static_cast<size_t>(u)] || in[static_cast<size_t>(u)] != value) continue;
            seen[static_cast<size_t>(u)] = 1;
            stack.push_back(u);
          }
    }
    return std::make_pair(size, border);
  };
  for (long long v = 0; v < total; ++v) {
    if (seen[static_cast<size_t>(v)]) continue;
    if (in[static_cast<size_t>(v)]) {
      ++t.components;
      t.single_voxel_components += fill(v, 1, true).first == 1;
    } else {
      const auto [size, border] = fill(v, 0, false);
      if (border) continue;
      ++t.cavities;
      t.single_voxel_cavities += size == 1;
    }
  }
  return t;
}

std::vector<SliceSpecks> slice_specks(const LabelVolume& mask) {
  const ImageGeometry& g = mask.geometry;
  auto in = [&](int i, int j, int k) {
    return i >= 0 && j >= 0 && i < g.size[0] && j < g.size[1] && mask.at(i, j, k) == 1;
  };
  std::vector<SliceSpecks> out;
  const IndexRange r = mask.range(1);  // a speck lies within the organ's box
  if (r.empty()) return out;
  for (int k = r.lo[2]; k <= r.hi[2]; ++k) {
    SliceSpecks s{k, 0, 0};
    for (int j = r.lo[1]; j <= r.hi[1]; ++j)
      for (int i = r.lo[0]; i <= r.hi[0]; ++i) {
        if (in(i, j, k)) {
          bool alone = true;
          for (int dj = -1; dj <= 1 && alone; ++dj)
            for (int di = -1; di <= 1 && alone; ++di)
              if ((di || dj) && in(i + di, j + dj, k)) alone = false;
          s.islands += alone;
        } else {
          s.holes += in(i - 1, j, k) && in(i + 1, j, k) && in(i, j - 1, k) && in(i, j + 1, k);
        }
      }
    if (s.islands || s.holes) out.push_back(s);
  }
  return out;
}

}  // namespace organfit::geometry
