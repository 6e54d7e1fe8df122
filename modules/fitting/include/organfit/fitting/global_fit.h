#pragma once
// Global stage of the "spread" fit: a volume-preserving affine map fitted to the points,
// and the model made to flow into the mapped shape.
//
// Why: a damped Lennard-Jones crystal is an elastic solid (METHOD.md s.8). Pulled by
// forces capped by F_max it stretches a little and springs back; it does not flow. A
// large, smooth change of shape (a stretch of 20%) is therefore done geometrically and
// the body re-made in its new shape at its own lattice density, which keeps the volume
// exactly: the same number of particles at the same density.
#include <Eigen/Core>
#include <vector>

#include "organfit/fitting/attractive_points.h"
#include "organfit/particles/state.h"

namespace organfit::fitting {

struct AffineFitOptions {
  int iterations = 60;
  double outlier_mads = 3.0;     ///< points beyond median + this x 1.4826 MAD get no weight
  double point_to_point = 0.1;   ///< weight of the point-to-point term beside point-to-plane
  double regularisation = 1e-3;  ///< pull of A towards I, relative to the points' spread
};

struct AffineFit {
  Eigen::Matrix3d a = Eigen::Matrix3d::Identity();  ///< det(a) = 1
  Eigen::Vector3d t = Eigen::Vector3d::Zero();
  double rms_before_mm = 0, rms_after_mm = 0;  ///< point-to-surface, over the kept points
  int iterations = 0;
};

/// Surface samples of a particle body: each skin centre pushed out by `radius_mm` along
/// its outward normal (away from the centroid of its neighbours within 1.6 r0).
struct SurfaceSamples {
  Eigen::Matrix3Xd points;   ///< mm
  Eigen::Matrix3Xd normals;  ///< unit, outward
};
SurfaceSamples surface_samples(const particles::Positions& x, const std::vector<int>& skin,
                               double radius_mm);

/// Robust ICP for x -> a x + t with det(a) = 1 matching the surface to the points:
/// point-to-plane (normals mapped by a^-T) plus a small point-to-point term, outliers
/// by a median + MAD rule, then det(a) = 1 by scaling at each iteration.
AffineFit fit_volume_preserving_affine(const SurfaceSamples& surface,
                                       const std::vector<AttractivePoint>& points,
                                       const AffineFitOptions& options);

/// The global map (affine, det 1).
struct GlobalMap {
  AffineFit affine;
  Eigen::Vector3d apply(const Eigen::Vector3d& p) const { return affine.a * p + affine.t; }
  Eigen::Vector3d inverse(const Eigen::Vector3d& q) const;
};

/// The body of `x` (balls of `radius_mm`, closed) mapped by `map` and re-filled with
/// exactly x.cols() particles: the deepest sites of an fcc lattice of spacing `a_nn_mm`
/// inside the mapped body. Same count, same density: the same volume.
particles::Positions refill_mapped_body(const particles::Positions& x, double radius_mm,
                                        double a_nn_mm, const GlobalMap& map);

}  // namespace organfit::fitting
