// topology_of: pieces (26-connected) and sealed cavities (6-connected) of a mask.
#include "organfit/geometry/topology.h"

#include <gtest/gtest.h>

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

}  // namespace
}  // namespace organfit::geometry
