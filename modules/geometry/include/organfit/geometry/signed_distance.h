#pragma once
// The signed distance to a mask's boundary (mm), sampled at the voxel centres and
// interpolated trilinearly between them.
#include <Eigen/Core>
#include <array>
#include <memory>
#include <mutex>
#include <vector>

#include "organfit/geometry/block_maxima.h"
#include "organfit/geometry/grid_buffer.h"
#include "organfit/geometry/image_geometry.h"

namespace organfit::geometry {

class SignedDistance {
 public:
  /// From the non-zero voxels of `mask`. At a voxel centre the value is the exact
  /// distance to the nearest centre across the boundary less half the smallest spacing
  /// (the boundary lies half a voxel between them): negative inside, positive outside;
  /// then smoothed by a Gaussian of one voxel, which takes the voxels' steps out of a
  /// slanted boundary (its gradient there was up to 40 degrees off the normal).
  /// Unsmoothed (`smooth` false), its sign at every voxel centre is the mask's, and its
  /// zero level lies midway between centres across the boundary (shape-based
  /// interpolation: unbiased between thick slices, where the 0.5 level of a trilinear
  /// mask takes the union of two slices at their midplane).
  explicit SignedDistance(const LabelVolume& mask, bool smooth = true);

  /// This distance smoothed, as the constructor smooths it (the same values as
  /// SignedDistance(mask, true) from an unsmoothed one, without its two transforms).
  SignedDistance smoothed() const;

  /// The surface at `level_mm` as a distance to fit points to: this distance smoothed
  /// within each slice (the binomial of smoothed() along the grid's first two axes only),
  /// less the level. Within a slice it takes the pixels' steps out of a slanted boundary;
  /// across slices the interpolation by shape is kept (a binomial along slices of 2.5 to
  /// 5 mm would round the organ's ends by a fraction of a slice).
  SignedDistance smoothed_within_slices(double level_mm) const;

  /// Value at `p_mm` (mm), trilinear between voxel centres; beyond the grid, the value
  /// at the nearest point of the grid plus the distance to it. `gradient` (unit-free,
  /// about 1 in length near the boundary), when given, is the interpolant's gradient.
  double at(const Eigen::Vector3d& p_mm, Eigen::Vector3d* gradient = nullptr) const;

  /// Value at voxel centre (i, j, k), clamped to the grid.
  double at_voxel(int i, int j, int k) const;

  /// The interpolant's largest |gradient| within the grid (unit-free: mm per mm): on a cell
  /// the squared gradient is convex along each axis, so its largest value is at a corner,
  /// where the partials are the cell's edge differences over the spacings. Infinite for a
  /// mask without boundary. Found on the first call (a pass over the grid, on threads: make
  /// that call outside a parallel region), then kept; copies of this distance share it.
  double gradient_bound() const;
  /// A bound on |grad at()| over the ball of `radius_mm` about `p_mm`: at() changes by at
  /// most this times the distance between two points of the ball. Within the grid, the
  /// largest corner bound (as gradient_bound()'s) over the voxels of the cells the ball's
  /// box touches, read from their maxima by blocks of 4, 8, 16... voxels a side (at most 8
  /// blocks: a block at least the box's size): a thick-sliced mask's distance is steep
  /// only where its slices step, and the bound where a ball lies is near 1. One reaching
  /// beyond the grid: gradient_bound() with the distance term's unit slope in quadrature.
  double gradient_bound(const Eigen::Vector3d& p_mm, double radius_mm) const;

  /// The level c (mm) whose region {p : at(p) < c} has the volume of the voxels whose
  /// centres are inside (at_voxel < 0). A region's volume is the expected count of a
  /// grid's points in it, the grid shifted by a uniformly random part of a voxel: so the
  /// region at c, moved across a grid like this one, keeps the voxels' count on average.
  /// The zero level rounds the voxels' convex edges off (about 2% less than the voxels
  /// at 1 x 1 x 3 mm). c lies in the values' gap about zero, so every voxel centre keeps
  /// its side (an unsmoothed distance's gap is at least half the smallest spacing either
  /// way); where the gap is too narrow to reach the volume, at its end. The volume is
  /// measured by jittered samples in each voxel whose 27 neighbours are not all on one
  /// side (elsewhere the interpolant keeps their side), enough for a standard error of
  /// 1e-4 of it, each voxel's samples drawn by its place about the organ (not in the
  /// grid): the same level on any grid that holds the organ and a voxel about it. Found on
  /// the first call (passes over the grid, on threads: make that call outside a parallel
  /// region), then kept; copies of this distance share it. 0 for a mask without boundary.
  double volume_level() const;

  /// The organ's levels (mm), as a model file keeps them. level_mm: volume_level().
  /// by_slice_phase_mm: the level found as volume_level() is, apart for the samples in each
  /// quarter of the half slice between a voxel centre's plane and the midplane to the next
  /// (the grid's third axis; its slices): index t in [0, 1/8), [1/8, 1/4), [1/4, 3/8),
  /// [3/8, 1/2] of a slice from the nearest plane of centres. Between thick slices the
  /// interpolant cuts an oblique boundary's corners, so the volume wants a higher level
  /// there than at the slices (0.02 -> 0.16 mm on a kidney's 5 mm slices; across the
  /// pixels, within 0.02 mm): one level for all is generous at the slices and short between
  /// them, and an organ moved by less than a slice along them gains or loses up to 2% of
  /// its count with the phase (docs/decisions.md).
  using LevelsBySlicePhase = std::array<double, 4>;
  struct VolumeLevels {
    double level_mm = 0;
    LevelsBySlicePhase by_slice_phase_mm{};
  };
  /// Both levels, found together on first use (as volume_level() says).
  VolumeLevels volume_levels() const { return found_levels(); }
  /// Takes `levels` as volume_levels(): those found before for this same mask (a saved
  /// model's; finding them again takes 0.28 s on a 1.5 L liver). No effect once the levels
  /// are known. Throws std::invalid_argument unless each could_be_volume_level.
  void adopt_volume_levels(const VolumeLevels& levels) const;

  /// The organ's level at `p_mm` (mm): volume_levels().by_slice_phase_mm taken at the
  /// centres of their quarters (t = 1/16, 3/16, 5/16, 7/16) and joined linearly (beyond the
  /// first and last, their line extended), kept within half the smallest spacing of 0
  /// (within the unsmoothed values' gap: at a voxel centre, t = 0, every centre keeps its
  /// side). The organ is {p : at(p) < volume_level_at(p)}.
  double volume_level_at(const Eigen::Vector3d& p_mm) const;
  /// at(p_mm) - volume_level_at(p_mm): negative inside the organ; `gradient` as at()'s,
  /// less the level's.
  double beyond_level(const Eigen::Vector3d& p_mm, Eigen::Vector3d* gradient = nullptr) const;
  /// The largest |grad volume_level_at| (mm per mm): its steepest piece over a slice.
  double volume_level_slope() const;
  /// The largest volume_level_at over all places (mm).
  double highest_volume_level() const;

  const ImageGeometry& geometry() const { return geometry_; }

 private:
  SignedDistance(const ImageGeometry& geometry, const Eigen::Matrix3d& to_index)
      : geometry_(geometry), to_index_(to_index) {}  // no values yet
  void smooth();
  /// A new distance: this one's values through the binomial passes (x, y and, with
  /// `across_slices`, z), or copied where there is no boundary to smooth.
  SignedDistance smoothed_by_passes(bool across_slices) const;
  bool all_finite() const;
  /// p_mm's offset from the nearest plane of voxel centres along the third axis (slices,
  /// in [-1/2, 1/2]).
  double slice_offset(const Eigen::Vector3d& p_mm) const;
  ImageGeometry geometry_;
  Eigen::Matrix3d to_index_;  ///< physical offset -> index offset
  GridBuffer<double> values_;
  /// gradient_bound() and volume_level(), each found once on first use (most distances
  /// never need them).
  struct FoundOnce {
    std::once_flag found;
    double value = 0;
  };
  /// gradient_bound() and its voxels' squared corner bounds, by blocks.
  struct GradientBlocks : FoundOnce {
    BlockMaxima largest_sq;
  };
  std::shared_ptr<GradientBlocks> gradient_bound_ = std::make_shared<GradientBlocks>();
  struct FoundLevels : FoundOnce {
    VolumeLevels levels;
  };
  std::shared_ptr<FoundLevels> volume_level_ = std::make_shared<FoundLevels>();
  /// volume_levels(), found on first use.
  const VolumeLevels& found_levels() const;
};

/// SignedDistance(mask, false).at(p) at each column of `points_mm` (mm), without
/// transforming the whole grid: each voxel the interpolation reads gets the distance to
/// its nearest voxel across the boundary, found among the boundary's voxels (the nearest
/// always is one: its face neighbour towards the voxel would be nearer), summed as the
/// transform sums it. For a few thousand points on a grid of millions of voxels (the
/// transforms' cost is the grid's; this one's, the points' and the boundary's).
std::vector<double> signed_distance_at(const LabelVolume& mask, const Eigen::Matrix3Xd& points_mm);

/// Whether `level_mm` can be a volume level of a mask on `grid`: finite and within the
/// largest spacing of zero (a level lies in the unsmoothed values' gap about zero).
bool could_be_volume_level(double level_mm, const ImageGeometry& grid);

}  // namespace organfit::geometry
