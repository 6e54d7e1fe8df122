#pragma once
// The organ as the fitted model carries it: the reference body (the planning organ's
// mask that the particles were filled from) moved with the particles.
//
// Why: the particles' own body (balls of radius rho closed by rho) is bumpy at their
// scale, about 0.7 mm from a smooth organ before any fit (the "discretisation floor").
// The particles are the physics; the organ's surface should be the planning surface,
// moved as they move. At rest it is the planning organ exactly.
//
// A point q of the fitted configuration is pulled back to the reference in two steps:
//  1. the particles' local displacement, interpolated by moving least squares: an
//     affine field fitted around q to the particles within `support_mm` of q, with
//     weights w(r) = (1 - r^2/h^2)^3, sending each current position x_i to where the
//     particle was placed, x_i^0 (after the global map, before the local stage):
//         q0 = q + u(q),  u(x_i) ~ x_i^0 - x_i;
//     an affine field is exact for affine motion and extrapolates past the outermost
//     particles to the surface, which lies beyond them;
//  2. the global map's exact inverse (identity for the paper's method): r = M^-1(q0).
// q is inside when the reference mask is inside at r (the 0.5 level of its trilinear
// interpolation, geometry::inside_interpolated). Points with fewer than 4 particles
// within the support are outside.
#include <Eigen/Core>
#include <memory>
#include <vector>

#include "organfit/fitting/global_fit.h"
#include "organfit/geometry/image_geometry.h"
#include "organfit/particles/state.h"

namespace organfit::fitting {

class EmbeddedBody {
 public:
  /// `placed` and `current`: the same particles (3 x N, mm) where the global stage put
  /// them and where they are now. Throws std::invalid_argument when the counts differ,
  /// a position is not finite, or support_mm <= 0.
  EmbeddedBody(std::shared_ptr<const geometry::LabelVolume> reference, GlobalMap map,
               particles::Positions placed, particles::Positions current, double support_mm);

  /// The point of the reference that q came from (mm); NaN when no particle is near q.
  Eigen::Vector3d pull_back(const Eigen::Vector3d& q_mm) const;
  bool inside(const Eigen::Vector3d& q_mm) const;
  /// A box holding the body: the current particles' box widened by the support (mm).
  geometry::Aabb bounds() const;
  /// The body on a grid (label 1 inside); only the part of the grid within bounds() is
  /// evaluated, the local displacement on a lattice of a quarter of the support and
  /// interpolated trilinearly in between.
  geometry::LabelVolume on_grid(const geometry::ImageGeometry& grid) const;
  /// Volume (mm^3) by counting voxel centres on an axis-aligned grid of `voxel_mm`.
  double volume_mm3(double voxel_mm) const;

  double support_mm() const { return h_; }

 private:
  std::shared_ptr<const geometry::LabelVolume> reference_;
  GlobalMap map_;
  Eigen::Matrix3d map_inverse_a_;
  particles::Positions placed_, current_;
  double h_;
  // The particles bucketed on a grid of cells of size h_ from lo_ (mm), dims_ cells a
  // side: cell c holds cell_order_[cell_start_[c] .. cell_start_[c + 1]), ascending.
  Eigen::Vector3d lo_;
  Eigen::Vector3i dims_ = Eigen::Vector3i::Zero();
  std::vector<int> cell_start_, cell_order_;
  /// Step 1: q + u(q) (NaN when no particle is within the support of q); the support
  /// widens where the neighbours spread too little, unless told not to.
  Eigen::Vector3d unmove_locally(const Eigen::Vector3d& q_mm, bool widen_if_needed = true) const;
  /// Step 2: the global map's inverse.
  Eigen::Vector3d unmap_globally(const Eigen::Vector3d& q0_mm) const;
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
