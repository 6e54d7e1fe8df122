#pragma once
// A mask's topology as a planning system sees it: its pieces and the cavities they close.
//   components  connected pieces of label 1 (26-connected: voxels touching at a corner
//               are one piece)
//   cavities    connected pieces of the rest (6-connected, the complement's pairing)
//               that do not reach the grid's border: holes sealed inside the organ
// A one-voxel component is an island; a one-voxel cavity, a pinhole. The pair (26, 6)
// is the one for which a digital surface separates inside from outside.
#include <Eigen/Core>
#include <functional>
#include <vector>

#include "organfit/geometry/image_geometry.h"

namespace organfit::geometry {

struct Topology {
  int components = 0, cavities = 0;
  int single_voxel_components = 0, single_voxel_cavities = 0;
  bool operator==(const Topology& o) const {
    return components == o.components && cavities == o.cavities &&
           single_voxel_components == o.single_voxel_components &&
           single_voxel_cavities == o.single_voxel_cavities;
  }
};

/// The topology of label 1 of `mask` (only the box of its voxels plus one is visited).
Topology topology_of(const LabelVolume& mask);

/// The sizes (voxels), largest first, of the pieces of label 1 (26-connected) that hold
/// none of `points_mm` (3 x N; a point is in the piece of the voxel whose centre is
/// nearest it, when that voxel is labelled 1): the parts of an organ a particle model
/// leaves empty.
std::vector<long long> pieces_holding_none(const LabelVolume& mask,
                                           const Eigen::Matrix3Xd& points_mm);

/// One-pixel pieces of one slice k of label 1, as its contours show them: an island (a
/// voxel of the organ none of whose 8 in-slice neighbours is) and a hole (a voxel outside
/// whose 4 in-slice neighbours are all inside; the pair (8, 4) of slice_contours). Below
/// what the grid resolves, so never a change of shape a planning system should draw.
struct SliceSpecks {
  int k = 0;
  int islands = 0, holes = 0;
};

/// Whether voxel (i, j, k) of `mask` is a one-pixel island (`island`) or hole of its slice,
/// as slice_specks counts them; false outside the grid.
bool is_slice_speck(const LabelVolume& mask, int i, int j, int k, bool island);

/// Whether the one-pixel speck of a mask at voxel (i, j, k) is the planning organ's own,
/// moved there: the planning organ has a speck of the same kind at the voxel's pre-image
/// (is_slice_speck there; the pre-image is the caller's map). A one-pixel void of the
/// planning organ (a vessel left out of a grown liver) cut by another slice once the organ
/// moved is a real hole; a speck the planning organ does not have at its pre-image is the
/// grid's (a crevice whose mouth closed on the slice, a tip left behind).
using SpeckExplained = std::function<bool(int i, int j, int k, bool island)>;

/// The slices of label 1 of `mask` with at least one island or hole, by slice index; with
/// `explained`, only the specks it does not explain are counted.
std::vector<SliceSpecks> slice_specks(const LabelVolume& mask,
                                      const SpeckExplained& explained = nullptr);

/// What restore_topology changed.
struct TopologyRepair {
  int slice_islands_removed = 0, slice_holes_filled = 0;  ///< one-pixel specks
  int components_removed = 0, cavities_filled = 0;        ///< 3D pieces
  long long voxels_changed = 0;
};

/// Gives label 1 of `mask` back the topology of the planning organ on the same grid
/// (`planning`: its topology_of) where sampling broke it. `mask` is meant to be the image of
/// the planning organ under a one-to-one continuous map (the fit's phi, det(grad phi) > 0)
/// sampled at the voxel centres: that image has the planning organ's pieces and cavities,
/// and each of its one-pixel specks is one the planning organ has at its pre-image.
/// Sampling breaks this only where the organ is about a voxel thin or a crevice a voxel
/// wide (a crevice closing at one voxel seals what lies beyond as a cavity; a thin tip
/// leaves a voxel behind as an island). Repaired by the smallest change, in order: the
/// one-pixel islands and holes `explained` does not explain, removed and filled; then
/// pieces beyond the planning organ's count removed and cavities beyond its count filled,
/// the smallest first. What the planning organ has and the mask lost (a thin bridge broken,
/// a cavity opened) is not made up: topology_of still shows it.
TopologyRepair restore_topology(LabelVolume& mask, const Topology& planning,
                                const SpeckExplained& explained);

}  // namespace organfit::geometry
