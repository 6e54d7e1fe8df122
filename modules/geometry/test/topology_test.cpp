// topology_of: pieces (26-connected) and sealed cavities (6-connected) of a mask.
#include "organfit/geometry/topology.h"

#include <gtest/gtest.h>

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

}  // namespace
}  // namespace organfit::geometry
