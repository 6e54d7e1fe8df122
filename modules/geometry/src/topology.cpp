#include "organfit/geometry/topology.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <cstdlib>
#include <vector>

namespace organfit::geometry {
namespace {

/// The connected pieces of a mask's label 1 (26-connected) and of the rest (6-connected),
/// on the box of its voxels plus a layer of background all round (outside the grid counts
/// as background), so that the outside is one piece touching the box's border.
struct Pieces {
  IndexRange box;
  int n[3] = {0, 0, 0};
  std::vector<int> id;  ///< each padded voxel's piece
  struct Piece {
    bool organ = false;   ///< a piece of label 1, or of the rest
    bool border = false;  ///< reaches the padded box's border (the outside)
    long long size = 0;   ///< voxels
  };
  std::vector<Piece> pieces;

  explicit Pieces(const LabelVolume& mask) : box(mask.range(1)) {
    if (box.empty()) return;
    for (int d = 0; d < 3; ++d)
      n[d] = box.hi[d] - box.lo[d] + 3;
    const long long total = 1LL * n[0] * n[1] * n[2];
    std::vector<std::uint8_t> in(static_cast<size_t>(total), 0);
    for (int k = 1; k + 1 < n[2]; ++k)
      for (int j = 1; j + 1 < n[1]; ++j)
        for (int i = 1; i + 1 < n[0]; ++i)
          in[index(i, j, k)] =
              mask.at(box.lo[0] + i - 1, box.lo[1] + j - 1, box.lo[2] + k - 1) == 1;
    id.assign(static_cast<size_t>(total), -1);
    std::vector<long long> stack;
    for (long long v = 0; v < total; ++v) {
      if (id[static_cast<size_t>(v)] >= 0) continue;
      const bool organ = in[static_cast<size_t>(v)];
      Piece p{organ, false, 0};
      const int label = static_cast<int>(pieces.size());
      stack.assign(1, v);
      id[static_cast<size_t>(v)] = label;
      while (!stack.empty()) {
        const long long w = stack.back();
        stack.pop_back();
        ++p.size;
        const int i = static_cast<int>(w % n[0]), j = static_cast<int>((w / n[0]) % n[1]),
                  k = static_cast<int>(w / (1LL * n[0] * n[1]));
        if (i == 0 || j == 0 || k == 0 || i == n[0] - 1 || j == n[1] - 1 || k == n[2] - 1)
          p.border = true;
        for (int dk = -1; dk <= 1; ++dk)
          for (int dj = -1; dj <= 1; ++dj)
            for (int di = -1; di <= 1; ++di) {
              const int steps = std::abs(di) + std::abs(dj) + std::abs(dk);
              if (steps == 0 || (!organ && steps > 1)) continue;
              const int a = i + di, b = j + dj, c = k + dk;
              if (a < 0 || b < 0 || c < 0 || a >= n[0] || b >= n[1] || c >= n[2]) continue;
              const size_t u = index(a, b, c);
              if (id[u] >= 0 || in[u] != organ) continue;
              id[u] = label;
              stack.push_back(static_cast<long long>(u));
            }
      }
      pieces.push_back(p);
    }
  }
  size_t index(int i, int j, int k) const {
    return static_cast<size_t>(i + 1LL * n[0] * (j + 1LL * n[1] * k));
  }
  bool cavity(const Piece& p) const { return !p.organ && !p.border; }
  Topology topology() const {
    Topology t;
    for (const Piece& p : pieces) {
      if (p.organ) ++t.components, t.single_voxel_components += p.size == 1;
      if (cavity(p)) ++t.cavities, t.single_voxel_cavities += p.size == 1;
    }
    return t;
  }
  /// Sets every voxel of the pieces `which` (flags by piece) to `label` in `mask`.
  long long set(LabelVolume& mask, const std::vector<bool>& which, std::uint8_t label) const {
    long long changed = 0;
    for (int k = 1; k + 1 < n[2]; ++k)
      for (int j = 1; j + 1 < n[1]; ++j)
        for (int i = 1; i + 1 < n[0]; ++i)
          if (which[static_cast<size_t>(id[index(i, j, k)])]) {
            mask.at(box.lo[0] + i - 1, box.lo[1] + j - 1, box.lo[2] + k - 1) = label;
            ++changed;
          }
    return changed;
  }
  /// The pieces of one kind beyond the `keep` largest, flagged; how many.
  int smallest_beyond(bool want_cavities, int keep, std::vector<bool>& flags) const {
    std::vector<int> of_kind;
    for (size_t p = 0; p < pieces.size(); ++p)
      if (want_cavities ? cavity(pieces[p]) : pieces[p].organ)
        of_kind.push_back(static_cast<int>(p));
    flags.assign(pieces.size(), false);
    if (static_cast<int>(of_kind.size()) <= keep) return 0;
    std::stable_sort(of_kind.begin(), of_kind.end(), [&](int a, int b) {
      return pieces[static_cast<size_t>(a)].size > pieces[static_cast<size_t>(b)].size;
    });
    for (size_t q = static_cast<size_t>(std::max(keep, 0)); q < of_kind.size(); ++q)
      flags[static_cast<size_t>(of_kind[q])] = true;
    return static_cast<int>(of_kind.size()) - std::max(keep, 0);
  }
};

/// One slice's one-pixel islands (label 1 with none of its 8 in-slice neighbours) and
/// holes (not label 1 with its 4 in-slice neighbours all label 1), visited in order.
template <class Visit>
void for_each_speck(const LabelVolume& mask, int k, const IndexRange& r, Visit&& visit) {
  const ImageGeometry& g = mask.geometry;
  auto in = [&](int i, int j) {
    return i >= 0 && j >= 0 && i < g.size[0] && j < g.size[1] && mask.at(i, j, k) == 1;
  };
  for (int j = r.lo[1]; j <= r.hi[1]; ++j)
    for (int i = r.lo[0]; i <= r.hi[0]; ++i) {
      if (in(i, j)) {
        bool alone = true;
        for (int dj = -1; dj <= 1 && alone; ++dj)
          for (int di = -1; di <= 1 && alone; ++di)
            if ((di || dj) && in(i + di, j + dj)) alone = false;
        if (alone) visit(i, j, true);
      } else if (in(i - 1, j) && in(i + 1, j) && in(i, j - 1) && in(i, j + 1)) {
        visit(i, j, false);
      }
    }
}

}  // namespace

bool is_slice_speck(const LabelVolume& mask, int i, int j, int k, bool island) {
  const ImageGeometry& g = mask.geometry;
  if (i < 0 || j < 0 || k < 0 || i >= g.size[0] || j >= g.size[1] || k >= g.size[2]) return false;
  bool found = false;
  const IndexRange one{{i, j, k}, {i, j, k}};
  for_each_speck(mask, k, one, [&](int, int, bool is_island) { found = is_island == island; });
  return found;
}

Topology topology_of(const LabelVolume& mask) {
  return Pieces(mask).topology();
}

std::vector<long long> pieces_holding_none(const LabelVolume& mask,
                                           const Eigen::Matrix3Xd& points_mm) {
  const Pieces pieces(mask);
  if (pieces.box.empty()) return {};
  std::vector<bool> held(pieces.pieces.size(), false);
  const ImageGeometry& g = mask.geometry;
  for (Eigen::Index c = 0; c < points_mm.cols(); ++c) {
    const Eigen::Vector3d idx = g.physical_to_index(points_mm.col(c));
    if (!idx.allFinite()) continue;
    const long long i = std::llround(idx.x()), j = std::llround(idx.y()), k = std::llround(idx.z());
    if (i < pieces.box.lo[0] || j < pieces.box.lo[1] || k < pieces.box.lo[2] ||
        i > pieces.box.hi[0] || j > pieces.box.hi[1] || k > pieces.box.hi[2])
      continue;
    const int p = pieces.id[pieces.index(static_cast<int>(i - pieces.box.lo[0] + 1),
                                         static_cast<int>(j - pieces.box.lo[1] + 1),
                                         static_cast<int>(k - pieces.box.lo[2] + 1))];
    if (p >= 0 && pieces.pieces[static_cast<size_t>(p)].organ) held[static_cast<size_t>(p)] = true;
  }
  std::vector<long long> sizes;
  for (size_t p = 0; p < pieces.pieces.size(); ++p)
    if (pieces.pieces[p].organ && !held[p]) sizes.push_back(pieces.pieces[p].size);
  std::sort(sizes.rbegin(), sizes.rend());
  return sizes;
}

std::vector<SliceSpecks> slice_specks(const LabelVolume& mask, const SpeckExplained& explained) {
  std::vector<SliceSpecks> out;
  const IndexRange r = mask.range(1);  // a speck lies within the organ's box
  if (r.empty()) return out;
  for (int k = r.lo[2]; k <= r.hi[2]; ++k) {
    SliceSpecks s{k, 0, 0};
    for_each_speck(mask, k, r, [&](int i, int j, bool island) {
      if (explained && explained(i, j, k, island)) return;
      island ? ++s.islands : ++s.holes;
    });
    if (s.islands || s.holes) out.push_back(s);
  }
  return out;
}

TopologyRepair restore_topology(LabelVolume& mask, const Topology& want,
                                const SpeckExplained& explained) {
  TopologyRepair repair;
  // Slice by slice: the one-pixel specks the planning organ does not have at their
  // pre-images.
  const IndexRange r = mask.range(1);
  if (r.empty() || want.components == 0) return repair;
  for (int k = r.lo[2]; k <= r.hi[2]; ++k) {
    std::vector<std::array<int, 3>> flips;  // i, j, new label
    for_each_speck(mask, k, r, [&](int i, int j, bool island) {
      if (explained(i, j, k, island)) return;
      flips.push_back({i, j, island ? 0 : 1});
      island ? ++repair.slice_islands_removed : ++repair.slice_holes_filled;
    });
    for (const auto& f : flips)
      mask.at(f[0], f[1], k) = static_cast<std::uint8_t>(f[2]);
    repair.voxels_changed += static_cast<long long>(flips.size());
  }
  // In 3D: pieces beyond the planning organ's count removed, smallest first; then (the
  // pieces removed may have sat in a cavity) cavities beyond its count filled, smallest first.
  std::vector<bool> flags;
  {
    const Pieces pieces(mask);
    if ((repair.components_removed = pieces.smallest_beyond(false, want.components, flags)) > 0)
      repair.voxels_changed += pieces.set(mask, flags, 0);
  }
  {
    const Pieces pieces(mask);
    if ((repair.cavities_filled = pieces.smallest_beyond(true, want.cavities, flags)) > 0)
      repair.voxels_changed += pieces.set(mask, flags, 1);
  }
  return repair;
}

}  // namespace organfit::geometry
