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
    label_runs(in);
  }
  /// Labels the padded box by runs along x: a row's runs of one side, joined (union-find)
  /// to the runs of the same side they touch in the rows before it, 26-connected for the
  /// organ (the 4 rows j-1 or k-1 about it, a run's ends grown by a voxel) and 6-connected
  /// for the rest (rows j-1 and k-1, overlapping). Pieces are numbered in the order of their
  /// first voxel. Linear in the voxels and cache-friendly: a flood fill by a stack of voxels
  /// took a second on a 2.5 L organ's 15 million voxels (0.8 x 0.8 x 0.5 mm).
  void label_runs(const std::vector<std::uint8_t>& in) {
    struct Run {
      int start, end;  // [start, end) along x
      bool organ;
    };
    std::vector<Run> runs;
    const long long rows = 1LL * n[1] * n[2];
    std::vector<long long> row_first(static_cast<size_t>(rows) + 1, 0);
    for (long long r = 0; r < rows; ++r) {
      row_first[static_cast<size_t>(r)] = static_cast<long long>(runs.size());
      const std::uint8_t* row = in.data() + r * n[0];
      for (int a = 0; a < n[0];) {
        int b = a + 1;
        while (b < n[0] && row[b] == row[a])
          ++b;
        runs.push_back({a, b, row[a] != 0});
        a = b;
      }
    }
    row_first[static_cast<size_t>(rows)] = static_cast<long long>(runs.size());
    std::vector<long long> parent(runs.size());
    for (size_t r = 0; r < runs.size(); ++r)
      parent[r] = static_cast<long long>(r);
    auto find = [&parent](long long x) {
      while (parent[static_cast<size_t>(x)] != x)
        x = parent[static_cast<size_t>(x)] =
            parent[static_cast<size_t>(parent[static_cast<size_t>(x)])];
      return x;
    };
    auto join = [&](long long a, long long b) {
      a = find(a), b = find(b);
      if (a != b) parent[static_cast<size_t>(std::max(a, b))] = std::min(a, b);
    };
    for (int k = 0; k < n[2]; ++k)
      for (int j = 0; j < n[1]; ++j) {
        const long long row = j + 1LL * n[1] * k;
        const int before[4][2] = {{j - 1, k}, {j, k - 1}, {j - 1, k - 1}, {j + 1, k - 1}};
        for (int b = 0; b < 4; ++b) {
          const int jb = before[b][0], kb = before[b][1];
          if (jb < 0 || kb < 0 || jb >= n[1]) continue;
          const bool face = b < 2;  // a face neighbour row: the rest joins across it too
          const long long other = jb + 1LL * n[1] * kb;
          long long q = row_first[static_cast<size_t>(other)];
          const long long q_end = row_first[static_cast<size_t>(other) + 1];
          for (long long r = row_first[static_cast<size_t>(row)];
               r < row_first[static_cast<size_t>(row) + 1]; ++r) {
            const Run& run = runs[static_cast<size_t>(r)];
            if (!run.organ && !face) continue;
            const int grow = run.organ ? 1 : 0;  // diagonal neighbours along x
            while (q < q_end && runs[static_cast<size_t>(q)].end + grow <= run.start)
              ++q;
            for (long long t = q; t < q_end && runs[static_cast<size_t>(t)].start < run.end + grow;
                 ++t)
              if (runs[static_cast<size_t>(t)].organ == run.organ &&
                  runs[static_cast<size_t>(t)].end + grow > run.start)
                join(r, t);
          }
        }
      }
    // Pieces in the order of their first run (the first voxel's), sizes, the border.
    std::vector<int> label(runs.size(), -1);
    id.assign(static_cast<size_t>(1LL * rows * n[0]), -1);
    for (long long row = 0; row < rows; ++row) {
      const int j = static_cast<int>(row % n[1]), k = static_cast<int>(row / n[1]);
      const bool edge_row = j == 0 || k == 0 || j == n[1] - 1 || k == n[2] - 1;
      for (long long r = row_first[static_cast<size_t>(row)];
           r < row_first[static_cast<size_t>(row) + 1]; ++r) {
        const Run& run = runs[static_cast<size_t>(r)];
        const auto root = static_cast<size_t>(find(r));
        if (label[root] < 0) {
          label[root] = static_cast<int>(pieces.size());
          pieces.push_back({run.organ, false, 0});
        }
        Piece& p = pieces[static_cast<size_t>(label[root])];
        p.size += run.end - run.start;
        p.border = p.border || edge_row || run.start == 0 || run.end == n[0];
        std::fill(id.begin() + row * n[0] + run.start, id.begin() + row * n[0] + run.end,
                  label[root]);
      }
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
