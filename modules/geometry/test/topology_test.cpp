// topology_of: pieces (26-connected) and sealed cavities (6-connected) of a mask.
#include "organfit/geometry/topology.h"

#include <gtest/gtest.h>

#include <array>
#include <cmath>
#include <cstdlib>
#include <random>
#include <vector>

#include "organfit/geometry/slice_contours.h"

namespace organfit::geometry {
namespace {

LabelVolume box_mask(int n) {
  ImageGeometry g;
  g.size = {n, n, n};
  LabelVolume m(g);
  for (int k = 2; k < n - 2; ++k)
    for (int j = 2; j < n - 2; ++j)
      for (int i = 2; i < n - 2; ++i)
        m.at(i, j, k) = 1;
  return m;
}

TEST(Topology, CountsPiecesCavitiesAndSingleVoxels) {
  LabelVolume m = box_mask(12);
  EXPECT_EQ(topology_of(m), (Topology{1, 0, 0, 0}));
  m.at(6, 6, 6) = 0;  // a pinhole inside
  EXPECT_EQ(topology_of(m), (Topology{1, 1, 0, 1}));
  for (int i = 4; i < 7; ++i)  // a larger cavity of 3 voxels
    m.at(i, 4, 4) = 0;
  EXPECT_EQ(topology_of(m), (Topology{1, 2, 0, 1}));
  m.at(0, 0, 0) = 1;  // an island at the grid's corner
  EXPECT_EQ(topology_of(m), (Topology{2, 2, 1, 1}));
  m.at(1, 1, 1) = 1;  // touching the box at a corner: one piece again (26-connected)
  EXPECT_EQ(topology_of(m).components, 1);
  LabelVolume open = box_mask(12);  // a hole through to the outside is no cavity
  for (int k = 0; k < 12; ++k)
    open.at(6, 6, k) = 0;
  EXPECT_EQ(topology_of(open), (Topology{1, 0, 0, 0}));
  EXPECT_EQ(topology_of(LabelVolume(ImageGeometry{})), (Topology{}));
}

// The pieces no point lies in, largest first: the box and two islands, a point in the box
// and one in the larger island (at a voxel's corner: its nearest centre's piece); points
// off the grid, in the background or NaN count for nothing.
/// The reference: a voxel-by-voxel flood fill of the grid grown by a layer of background,
/// label 1 26-connected, the rest 6-connected; pieces, cavities and single voxels counted.
Topology flood_fill_topology(const LabelVolume& m) {
  const int n[3] = {m.geometry.size[0] + 2, m.geometry.size[1] + 2, m.geometry.size[2] + 2};
  auto in = [&](int i, int j, int k) {
    return i > 0 && j > 0 && k > 0 && i < n[0] - 1 && j < n[1] - 1 && k < n[2] - 1 &&
           m.at(i - 1, j - 1, k - 1) == 1;
  };
  std::vector<char> seen(static_cast<size_t>(n[0]) * n[1] * n[2], 0);
  auto at = [&](int i, int j, int k) { return static_cast<size_t>(i + n[0] * (j + n[1] * k)); };
  Topology t;
  for (int k = 0; k < n[2]; ++k)
    for (int j = 0; j < n[1]; ++j)
      for (int i = 0; i < n[0]; ++i) {
        if (seen[at(i, j, k)]) continue;
        const bool organ = in(i, j, k);
        bool border = false;
        long long size = 0;
        std::vector<std::array<int, 3>> stack = {{i, j, k}};
        seen[at(i, j, k)] = 1;
        while (!stack.empty()) {
          const auto [a, b, c] = stack.back();
          stack.pop_back();
          ++size;
          border = border || a == 0 || b == 0 || c == 0 || a == n[0] - 1 || b == n[1] - 1 ||
                   c == n[2] - 1;
          for (int dk = -1; dk <= 1; ++dk)
            for (int dj = -1; dj <= 1; ++dj)
              for (int di = -1; di <= 1; ++di) {
                const int steps = std::abs(di) + std::abs(dj) + std::abs(dk);
                if (steps == 0 || (!organ && steps > 1)) continue;
                const int x = a + di, y = b + dj, z = c + dk;
                if (x < 0 || y < 0 || z < 0 || x >= n[0] || y >= n[1] || z >= n[2]) continue;
                if (seen[at(x, y, z)] || in(x, y, z) != organ) continue;
                seen[at(x, y, z)] = 1;
                stack.push_back({x, y, z});
              }
        }
        if (organ) ++t.components, t.single_voxel_components += size == 1;
        if (!organ && !border) ++t.cavities, t.single_voxel_cavities += size == 1;
      }
  return t;
}

TEST(Topology, CountsAsAVoxelFloodFillDoesOnRandomMasks) {
  // Random masks from sparse (many diagonal-only contacts) to dense (many sealed cavities),
  // on grids of odd shapes, and the organ touching the grid's edges.
  std::mt19937 rng(7);
  for (int trial = 0; trial < 40; ++trial) {
    ImageGeometry g;
    g.size = {3 + trial % 9, 4 + trial % 5, 2 + trial % 7};
    LabelVolume m(g);
    const unsigned percent = 10 + 2 * trial;
    for (auto& v : m.labels)
      v = rng() % 100 < percent ? 1 : (rng() % 9 == 0 ? 2 : 0);  // label 2 is not the organ
    EXPECT_EQ(topology_of(m), flood_fill_topology(m)) << "trial " << trial;
  }
}

TEST(PiecesHoldingNone, AreThePiecesNoPointLiesIn) {
  LabelVolume m = box_mask(16);             // voxels 2..13 (unit voxels, origin 0)
  m.at(0, 0, 0) = 1;                        // an island of one voxel
  m.at(15, 15, 15) = m.at(15, 15, 14) = 1;  // one of two
  Eigen::Matrix3Xd none(3, 0);
  EXPECT_EQ(pieces_holding_none(m, none), (std::vector<long long>{12 * 12 * 12, 2, 1}));
  Eigen::Matrix3Xd points(3, 5);
  points.col(0) << 6, 7, 8;
  points.col(1) << 15.4, 14.6, 14.4;  // nearest centre (15, 15, 14)
  points.col(2) << 50, 0, 0;
  points.col(3) << 0, 15, 0;
  points.col(4) << std::nan(""), 0, 0;
  EXPECT_EQ(pieces_holding_none(m, points), (std::vector<long long>{1}));
  EXPECT_TRUE(pieces_holding_none(LabelVolume(ImageGeometry{}), points).empty());
}

// Per-slice contour counts: a hole punched through one slice and an island beside the
// box on another are each one more contour there; a slice only one organ cuts is no
// change (the organ moved onto it).
TEST(ContourCountChanges, NameTheSlicesBothOrgansCutWhoseCountDiffers) {
  const LabelVolume before = box_mask(12);
  LabelVolume after = box_mask(12);
  after.at(6, 6, 4) = 0;  // a hole in slice 4
  after.at(0, 0, 7) = 1;  // an island on slice 7
  for (int j = 2; j < 10; ++j)
    for (int i = 2; i < 10; ++i)
      after.at(i, j, 10) = 1;  // slice 10: the organ moved onto it
  const std::vector<ContourCountChange> c =
      contour_count_changes(slice_contours(before, 1), slice_contours(after, 1));
  ASSERT_EQ(c.size(), 2u);
  EXPECT_EQ(c[0].k, 4);
  EXPECT_EQ(c[0].before, 1);
  EXPECT_EQ(c[0].after, 2);
  EXPECT_EQ(c[1].k, 7);
  EXPECT_EQ(c[1].after, 2);
  EXPECT_TRUE(contour_count_changes(slice_contours(before, 1), slice_contours(before, 1)).empty());
}

// One-pixel islands and holes of a slice: a voxel none of whose 8 in-slice neighbours is
// in, and a voxel missing with its 4 neighbours in; a voxel touching the organ only
// diagonally is no island (it is on the organ's contour).
TEST(SliceSpecks, CountOnePixelIslandsAndHolesPerSlice) {
  LabelVolume m = box_mask(12);
  EXPECT_TRUE(slice_specks(m).empty());
  m.at(6, 6, 4) = 0;  // a hole in slice 4
  m.at(0, 5, 7) = 1;  // an island on slice 7
  m.at(1, 1, 3) = 1;  // diagonal to the box's corner (2, 2, 3): no island
  const std::vector<SliceSpecks> s = slice_specks(m);
  ASSERT_EQ(s.size(), 2u);
  EXPECT_EQ(s[0].k, 4);
  EXPECT_EQ(s[0].holes, 1);
  EXPECT_EQ(s[0].islands, 0);
  EXPECT_EQ(s[1].k, 7);
  EXPECT_EQ(s[1].islands, 1);
  EXPECT_EQ(s[1].holes, 0);
  // Contours: one on each of the box's 8 slices, one more for the hole and for the island;
  // the diagonal voxel joins the contour of slice 3.
  EXPECT_EQ(slice_contours(m, 1).size(), 10u);
}

// restore_topology: a crevice one voxel wide that closed at its mouth (a sealed cavity), a
// voxel left behind off the organ (an island in 3D and on its slice) and a one-pixel hole
// are undone, and nothing else changes; what the planning organ has itself is kept.
/// The identity's SpeckExplained: the speck is `planning`'s own when `planning` has a
/// speck of the same kind at the same voxel.
SpeckExplained in_place(const LabelVolume& planning) {
  return [&planning](int i, int j, int k, bool island) {
    return is_slice_speck(planning, i, j, k, island);
  };
}

TEST(RestoreTopology, UndoesSamplingArtefactsTheMapCannotMake) {
  const LabelVolume planning = box_mask(14);
  LabelVolume sampled = planning;
  sampled.at(5, 5, 5) = 0, sampled.at(6, 5, 5) = 0;  // a sealed cavity of 2 voxels
  sampled.at(8, 8, 8) = 0;                           // a pinhole, also a one-pixel hole
  sampled.at(0, 6, 6) = 1;                           // an island one voxel off the box
  ASSERT_EQ(topology_of(sampled), (Topology{2, 2, 1, 1}));
  const TopologyRepair r = restore_topology(sampled, topology_of(planning), in_place(planning));
  EXPECT_EQ(topology_of(sampled), topology_of(planning));
  EXPECT_EQ(sampled.labels, planning.labels);
  EXPECT_EQ(r.slice_islands_removed, 1);
  EXPECT_EQ(r.slice_holes_filled, 1);  // the pinhole; the 2-voxel cavity is no speck
  EXPECT_EQ(r.components_removed, 0);  // the island went as a speck
  EXPECT_EQ(r.cavities_filled, 1);
  EXPECT_EQ(r.voxels_changed, 4);

  // An island of two voxels side by side in a slice is no speck: removed as the smaller piece.
  LabelVolume two = planning;
  two.at(0, 6, 6) = 1, two.at(0, 7, 6) = 1;
  EXPECT_EQ(restore_topology(two, topology_of(planning), in_place(planning)).components_removed, 1);
  EXPECT_EQ(two.labels, planning.labels);

  // The planning organ's own cavity and one-pixel hole are kept; a broken piece is not
  // made up (the planning organ has two, the sampled one lost the small one).
  LabelVolume holed = planning;
  holed.at(6, 6, 6) = 0;
  holed.at(0, 0, 0) = 1;
  LabelVolume same = holed;
  const TopologyRepair none = restore_topology(same, topology_of(holed), in_place(holed));
  EXPECT_EQ(none.voxels_changed, 0);
  EXPECT_EQ(same.labels, holed.labels);
  LabelVolume lost = holed;
  lost.at(0, 0, 0) = 0;
  EXPECT_EQ(restore_topology(lost, topology_of(holed), in_place(holed)).voxels_changed, 0);
  EXPECT_EQ(topology_of(lost).components, 1);
}

// A one-pixel void of the planning organ moved by the map onto another slice (a vessel
// left out of a grown liver, cut by a slice once the organ moved): a real hole, kept, and
// not counted by slice_specks given the map; a hole the planning organ does not have at
// its pre-image is the grid's, filled, and so is one whose pre-image is outside the organ
// but no hole there (a crevice open to the outside whose mouth closed on the slice). The
// rule is the pre-image's, not the slice's: the slice the void moved to had no hole before.
TEST(RestoreTopology, KeepsAHoleThePlanningOrganHasWhereItCameFrom) {
  LabelVolume planning = box_mask(14);
  planning.at(6, 6, 5) = 0;  // a one-pixel void on slice 5
  LabelVolume moved = box_mask(14);
  moved.at(6, 6, 6) = 0;                               // the void moved up a slice
  moved.at(9, 9, 6) = 0;                               // and a hole the planning organ has not
  planning.at(2, 3, 5) = 0, planning.at(3, 3, 5) = 0;  // a crevice from the box's side
  moved.at(3, 3, 6) = 0;  // its end, its mouth closed on the slice: a hole
  // The map moves everything up a slice: the pre-image of (i, j, k) is (i, j, k - 1).
  const SpeckExplained moved_up = [&planning](int i, int j, int k, bool island) {
    return is_slice_speck(planning, i, j, k - 1, island);
  };
  const std::vector<SliceSpecks> unexplained = slice_specks(moved, moved_up);
  ASSERT_EQ(unexplained.size(), 1u);
  EXPECT_EQ(unexplained[0].k, 6);
  EXPECT_EQ(unexplained[0].holes, 2);
  const TopologyRepair r = restore_topology(moved, topology_of(planning), moved_up);
  EXPECT_EQ(r.slice_holes_filled, 2);
  EXPECT_EQ(moved.at(9, 9, 6), 1);
  EXPECT_EQ(moved.at(3, 3, 6), 1);
  EXPECT_EQ(moved.at(6, 6, 6), 0);  // kept
  EXPECT_TRUE(slice_specks(moved, moved_up).empty());
  EXPECT_EQ(topology_of(moved), topology_of(planning));
}

}  // namespace
}  // namespace organfit::geometry
