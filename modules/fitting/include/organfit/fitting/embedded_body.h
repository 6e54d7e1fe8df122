#pragma once
// The organ as the fitted model carries it: the reference body (the planning organ's
// mask that the particles were filled from) moved with the particles.
//
// Why: the particles' own body (balls of radius rho closed by rho) is bumpy at their
// scale, about 0.7 mm from a smooth organ before any fit (the "discretisation floor").
// The particles are the physics; the organ's surface should be the planning surface,
// moved as they move. At rest it is the planning organ exactly.
//
// A point q of the fitted configuration is inside when phi^-1(q), the fit's deformation
// pulled back (deformation.h: defined at every point), is inside the reference mask: its
// signed distance, unsmoothed and trilinear, is below its volume level there
// (geometry/signed_distance.h). At a voxel centre of the reference's grid that is the
// mask's own label; between slices the surface is interpolated by shape, so that moving
// the organ by part of a slice neither adds nor removes a slice's worth of volume; and
// the level, not zero, so that the voxels' convex edges are not rounded off: moved by
// parts of a voxel, the organ keeps its voxel count on average.
#include <Eigen/Core>
#include <functional>
#include <memory>
#include <vector>

#include "organfit/fitting/deformation.h"
#include "organfit/fitting/global_fit.h"
#include "organfit/geometry/image_geometry.h"
#include "organfit/geometry/signed_distance.h"
#include "organfit/particles/state.h"

namespace organfit::fitting {

class EmbeddedBody {
 public:
  /// `placed` and `current`: the same particles (3 x N, mm) where the global stage put
  /// them and where they are now (see Deformation, which throws std::invalid_argument on
  /// bad input).
  EmbeddedBody(std::shared_ptr<const geometry::LabelVolume> reference, GlobalMap map,
               particles::Positions placed, particles::Positions current, double support_mm);
  /// The reference moved by a deformation already made.
  EmbeddedBody(std::shared_ptr<const geometry::LabelVolume> reference,
               std::shared_ptr<const Deformation> deformation);
  /// The same with the reference's unsmoothed signed distance already made (it costs two
  /// distance transforms of the reference's grid: a second on a 2 L organ).
  EmbeddedBody(std::shared_ptr<const geometry::LabelVolume> reference,
               std::shared_ptr<const geometry::SignedDistance> distance,
               std::shared_ptr<const Deformation> deformation);

  /// The point of the reference that q came from (mm): phi^-1(q).
  Eigen::Vector3d pull_back(const Eigen::Vector3d& q_mm) const {
    return deformation_->pull_back(q_mm);
  }
  bool inside(const Eigen::Vector3d& q_mm) const;
  /// The levels of the reference's signed distance that bound the body (mm; inside where
  /// d(phi^-1(q)) < the level at phi^-1(q)'s place between the reference's slices):
  /// SignedDistance::volume_levels, so that the body keeps its voxel count on a grid it
  /// moves across by parts of a voxel, whatever the part along the slices. Found on first
  /// use (0.05 to 0.3 s on a real organ), so a body asked only for its deformation does not
  /// pay for it.
  geometry::SignedDistance::VolumeLevels levels() const { return distance_->volume_levels(); }
  /// A box holding the body (mm): the particles' box (Deformation::particle_box) and the
  /// planning organ's surface moved by phi, which also holds the parts of the organ no
  /// particle fills (an island of a few voxels, a part thinner than the lattice).
  geometry::Aabb bounds() const { return bounds_; }
  /// The body on a grid (label 1 inside); only the part of the grid within bounds() is
  /// evaluated.
  geometry::LabelVolume on_grid(const geometry::ImageGeometry& grid) const;
  /// Volume (mm^3) by counting voxel centres on an axis-aligned grid of `voxel_mm`.
  double volume_mm3(double voxel_mm) const;
  /// The body's volume (mm^3) on `count` copies of `grid` moved by parts of a voxel (the
  /// Halton points of bases 2, 3 and 5 over the voxel, centred on it: moves from -1/2 to
  /// 1/2 of a voxel along each of the grid's axes), in that order. What the grid's phase
  /// alone does to a voxel count of this body: between thick slices a slice's worth at its
  /// ends, the same along a whole contour, and heavy-tailed, which no model of independent
  /// errors at the boundary voxels gives. Their mean is the body's volume without it.
  std::vector<double> volumes_on_shifted_grids(const geometry::ImageGeometry& grid,
                                               int count) const;
  /// `measure` of the body on each of the same copies of `grid`, in that order.
  std::vector<double> on_shifted_grids(
      const geometry::ImageGeometry& grid, int count,
      const std::function<double(const geometry::LabelVolume&)>& measure) const;
  /// The organ's volume today over its planning volume, from the deformation's Jacobian
  /// over `organ` (this body on some grid): N / sum of det(grad phi^-1) over its N
  /// voxels. Both sums count the same voxels, so the grid's sampling of the surface,
  /// which makes two voxel counts of one volume differ by up to a percent between thick
  /// slices, cancels: 1 exactly where phi keeps volume.
  double volume_ratio(const geometry::LabelVolume& organ) const;

  double support_mm() const { return deformation_->support_mm(); }
  const Deformation& deformation() const { return *deformation_; }
  std::shared_ptr<const Deformation> shared_deformation() const { return deformation_; }
  const geometry::LabelVolume& reference() const { return *reference_; }
  std::shared_ptr<const geometry::LabelVolume> shared_reference() const { return reference_; }
  std::shared_ptr<const geometry::SignedDistance> shared_distance() const { return distance_; }

 private:
  std::shared_ptr<const geometry::LabelVolume> reference_;
  std::shared_ptr<const geometry::SignedDistance> distance_;
  std::shared_ptr<const Deformation> deformation_;
  geometry::Aabb bounds_;
};

/// Each particle's foot on a surface given by dense samples with outward normals: the
/// offset to its nearest sample (mm) and that sample's normal, found within `reach_mm`.
/// A particle with no sample within reach (deep inside, never skin) gets the offset
/// reach_mm along the direction from the particles' centroid. With the reference surface
/// moved by the global map (map_surface), these are what the spread force fits with, so
/// that the surface it moves onto the points is the embedded body's. O(N + samples).
SurfaceFeet surface_feet(const particles::Positions& x, const SurfaceSamples& surface,
                         double reach_mm);

/// Moving-least-squares support for a model of lattice spacing `a_nn_mm`: 2 spacings,
/// so that a point on the surface, with particles on one side only, has ~20 of them
/// (and more where they spread too little: EmbeddedBody::pull_back).
inline double embedding_support_mm(double a_nn_mm) {
  return 2.0 * a_nn_mm;
}

}  // namespace organfit::fitting
