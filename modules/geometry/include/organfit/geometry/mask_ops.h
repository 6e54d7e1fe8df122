#pragma once
// Voxel masks of particle bodies, and the distances between their surfaces.
//
// Definitions (stated because published tools differ by up to 50% on these):
//  * Body of a particle set: the union of balls of radius `radius_mm` around the
//    centres, closed morphologically by `closing_mm` (dilate, then erode, by exact
//    Euclidean distance), so the gaps between packed spheres count as inside. Voxels
//    are cubes of `voxel_mm`, inside when their centre is.
//  * Surface of a mask: its voxels with at least one of their 6 face neighbours outside.
//  * Distance from a surface voxel of A to B: Euclidean distance (mm) from its centre to
//    the nearest surface-voxel centre of B.
//  * Mean surface distance (MSD): the mean over the surface voxels of A and of B
//    together of their distance to the other surface (symmetric). HD95: the 95th
//    percentile of that same pooled set of distances.
//  * Dice: 2 |A and B| / (|A| + |B|) on the common grid.
#include <Eigen/Core>
#include <cstdint>
#include <memory>
#include <vector>

#include "organfit/geometry/grid_buffer.h"
#include "organfit/geometry/image_geometry.h"

namespace organfit::geometry {

/// Squared Euclidean distance (mm^2) from every voxel to the nearest voxel where
/// `feature` is non-zero (infinity when there is none). Exact, linear time
/// (Felzenszwalb & Huttenlocher 2012), anisotropic spacing allowed; direction ignored.
GridBuffer<double> squared_distance_transform(const std::vector<std::uint8_t>& feature,
                                              const ImageGeometry& grid);

/// Squared Euclidean distance (mm^2) from every voxel to the nearest voxel of the other
/// side: from a voxel outside (`inside` zero) to the nearest inside, from one inside to
/// the nearest outside (infinity when the other side has none). The two transforms of
/// squared_distance_transform, each where it is asked, value for value, in one buffer.
GridBuffer<double> squared_distance_across(const std::vector<std::uint8_t>& inside,
                                           const ImageGeometry& grid);

/// For every voxel, the linear index of its nearest voxel where `feature` is non-zero (-1
/// when there is none): the argument of squared_distance_transform's minimum, by the same
/// exact linear-time passes. Of equidistant feature voxels one is taken, which one decided
/// by the passes' rounding. Grids of fewer than 2^31 voxels; std::invalid_argument
/// otherwise.
std::vector<int> nearest_feature_transform(const std::vector<std::uint8_t>& feature,
                                           const ImageGeometry& grid);

/// An axis-aligned grid of cubic voxels covering `box` grown by `margin_mm`.
ImageGeometry grid_covering(const Aabb& box, double voxel_mm, double margin_mm);

/// Balls of `radius_mm` at `centres` (3 x N, mm) rasterised on `grid` (label 1).
LabelVolume rasterize_balls(const Eigen::Matrix3Xd& centres, double radius_mm,
                            const ImageGeometry& grid);

/// Morphological closing by a ball of `radius_mm` (dilate then erode), in place.
void close_mask(LabelVolume& mask, double radius_mm);

/// The closed body of a particle set (balls of `radius_mm` closed by `closing_mm`, the
/// definition above) on the part of `grid` the balls and the closing reach, a voxel more
/// each side (clamped to the grid; no voxel when that part is empty): a grid of the same
/// spacing and direction whose voxels are some of grid's. Label 1 inside.
LabelVolume closed_body(const Eigen::Matrix3Xd& centres, double radius_mm, double closing_mm,
                        const ImageGeometry& grid);

/// The closed body of a particle set on `grid`: closed_body() placed on the whole grid (a
/// large CT costs no more than the organ's box). Label 1 inside.
LabelVolume closed_body_on_grid(const Eigen::Matrix3Xd& centres, double radius_mm,
                                double closing_mm, const ImageGeometry& grid);

/// The mask cropped to its voxels of label 1 and one voxel about them (within its grid),
/// labels 0 and 1: what a model file keeps of an organ, and where its signed distance is
/// made (one voxel about the organ holds every voxel's nearest across the boundary).
LabelVolume cropped_organ(const LabelVolume& mask);

/// Whether `p_mm` lies inside the surface of a mask taken as the 0.5 level of the
/// trilinear interpolation of its indicator (label 1 = 1, else 0; 0 off the grid). On a
/// CT mask with thick slices the surface then runs straight from slice to slice instead
/// of stepping by the slice gap, while voxel centres keep their labels.
bool inside_interpolated(const LabelVolume& mask, const Eigen::Vector3d& p_mm);

/// The surface voxels of a mask (label != 0 with a face neighbour outside or off-grid).
std::vector<std::uint8_t> surface_of(const LabelVolume& mask);

/// The same voxels listed: their indices (i, j, k) in the grid's order (i fastest),
/// found a slice per thread.
std::vector<Eigen::Vector3i> surface_voxels(const LabelVolume& mask);

struct SurfaceComparison {
  double msd_mm = 0;   ///< symmetric mean surface distance
  double hd95_mm = 0;  ///< symmetric 95th-percentile Hausdorff distance
  double dice = 0;
  double volume_a_mm3 = 0, volume_b_mm3 = 0;
};

/// A mask's surface voxels made ready for distance queries: their centres (mm, 3 x N,
/// ascending linear index; origin + index * spacing, the grid's axes taken as the
/// patient's as the distance transform takes them), as bits on the mask's lattice (a query
/// on it searches the offsets about it) and in a k-d tree (a query off it, or far from
/// the surface). Made once for a mask that is compared with several others.
class MaskSurface {
 public:
  explicit MaskSurface(const LabelVolume& mask);
  ~MaskSurface();
  MaskSurface(MaskSurface&&) noexcept;
  MaskSurface& operator=(MaskSurface&&) noexcept;
  const Eigen::Matrix3Xd& points_mm() const;
  /// Distance (mm) from each of `q`'s columns to the nearest surface voxel centre
  /// (infinity when the mask has none).
  std::vector<double> distances_from(const Eigen::Matrix3Xd& q) const;

 private:
  friend void surface_distances(const MaskSurface& a, const MaskSurface& b, SurfaceComparison& out);
  // distances_from in its two passes: `d` set for the queries near the surface on its
  // lattice, the others left at infinity and counted; then those, by the tree (built once,
  // by build_tree or the first far pass).
  long long near_distances(const Eigen::Matrix3Xd& q, std::vector<double>& d) const;
  void build_tree() const;
  void far_distances(const Eigen::Matrix3Xd& q, std::vector<double>& d) const;
  struct Search;  // the centres and their tree, where the tree's view of them stays put
  std::unique_ptr<Search> search_;
};

/// MSD and HD95 between two surfaces (the definitions above: the pooled distances of
/// each one's surface voxels to the other's), written into `out`.
void surface_distances(const MaskSurface& a, const MaskSurface& b, SurfaceComparison& out);

/// Compares two masks on the same grid.
SurfaceComparison compare_masks(const LabelVolume& a, const LabelVolume& b);

/// Volume (mm^3) of the closed body of a particle set (definition above).
double particle_body_volume_mm3(const Eigen::Matrix3Xd& centres, double radius_mm, double voxel_mm,
                                double closing_mm);

/// Compares the closed bodies of two particle sets on a common grid.
SurfaceComparison compare_particle_bodies(const Eigen::Matrix3Xd& a, const Eigen::Matrix3Xd& b,
                                          double radius_mm, double voxel_mm, double closing_mm);

}  // namespace organfit::geometry
