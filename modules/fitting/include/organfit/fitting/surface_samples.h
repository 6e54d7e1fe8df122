#pragma once
// Samples of an organ's surface, points with outward unit normals (mm): from a particle
// body's skin, or from its reference body's mask through the signed distance (denser and
// smoother). What the global map is fitted and judged on.
#include <Eigen/Core>
#include <cstdint>
#include <vector>

#include "organfit/geometry/image_geometry.h"
#include "organfit/geometry/signed_distance.h"
#include "organfit/particles/state.h"

namespace organfit::fitting {

/// Surface samples of a particle body: each skin centre pushed out by `radius_mm` along
/// its outward normal (away from the centroid of its neighbours within 1.6 r0).
struct SurfaceSamples {
  Eigen::Matrix3Xd points;   ///< mm
  Eigen::Matrix3Xd normals;  ///< unit, outward
  /// What one_in chooses by: a reference surface's sample's voxel (its linear index); empty
  /// for a particle body's.
  std::vector<std::uint64_t> keys;
  /// One in `stride` of these samples, in their order, chosen by key as reference_surface
  /// chooses its voxels: reference_surface(r, d, 1).one_in(s) is reference_surface(r, d, s).
  SurfaceSamples one_in(int stride) const;
};
SurfaceSamples surface_samples(const particles::Positions& x, const std::vector<int>& skin,
                               double radius_mm);

/// Surface samples of a reference body (a mask): one in `stride` boundary voxels (chosen
/// by a hash of the voxel's index: spread evenly over the surface, the same every run),
/// moved onto the zero level of the signed distance, with the distance's gradient as
/// normal. Denser and smoother than the particles' own surface.
SurfaceSamples reference_surface(const geometry::LabelVolume& reference, int stride = 1);
/// The same with the reference's signed distance already at hand (it is what costs).
SurfaceSamples reference_surface(const geometry::LabelVolume& reference,
                                 const geometry::SignedDistance& distance, int stride = 1);

}  // namespace organfit::fitting
