#pragma once
// The global stage's solvers (module-internal; global_fit.h says what they fit and why):
// the whole-map Gauss-Newton by closest samples, the fits on the reference's signed
// distance (with and without the volume constraint), the shear fields' ridge fit, and
// the measures they and the choice among their fits (global_fit.cpp) share.
#include <Eigen/Core>
#include <vector>

#include "mapped_samples.h"
#include "organfit/fitting/global_fit.h"
#include "organfit/geometry/signed_distance.h"

namespace organfit::fitting::detail {

/// Weights by the outlier rule (robust.h, on the residuals r): outliers get none, the
/// others their confidence. Returns the RMS of the kept residuals.
double robust_weights(const std::vector<double>& r, const std::vector<AttractivePoint>& points,
                      double mads, std::vector<double>& w);

/// Robust RMS (mm) of the points' distances to their nearest mapped surface samples, by
/// the fits' outlier rule: what refine_global_map reports of its maps.
double nearest_sample_rms(const MappedSamples& mapped, const std::vector<AttractivePoint>& points,
                          double mads);
double nearest_sample_rms(const GlobalMap& map, const SurfaceSamples& surface,
                          const std::vector<AttractivePoint>& points, double mads);

/// Gauss-Newton on the whole map (affine with det 1, then shears) from `map`, with the
/// stiffness annealed from 1000x the stated one when `anneal`. Only the first three shears
/// (c0..c8) are fitted here, their images linearised at the affine image: the last two
/// would repeat the second and the first to that order; the fit on the signed distance
/// fits all five. Returns the map as it was at the end of each stiffness level, the final
/// one last: each is a fit of the points by a stiffer map, a candidate in its own right.
std::vector<GlobalMap> refine_global_map(GlobalMap map, const SurfaceSamples& surface,
                                         const std::vector<AttractivePoint>& points,
                                         const AffineFitOptions& o, bool anneal);

/// The fit on the reference's signed distance (see fit_global_map): robust Gauss-Newton
/// on the points' mapped_distance, the shears fitted too when `with_shears`, each step on
/// the linearised volume constraint when `on_constraint` (else rescaled to det 1). Returns
/// the map at the end of each stiffness level, the final one last.
std::vector<GlobalMap> fit_to_distance(GlobalMap map, const geometry::SignedDistance& distance,
                                       const SurfaceSamples& surface,
                                       const std::vector<AttractivePoint>& points,
                                       const AffineFitOptions& o, bool with_shears,
                                       bool on_constraint);

/// Smooth shear fields on top of `map` (its affine part and quadratic shears held): robust
/// Gauss-Newton on the points' mapped_distance, Geman-McClure weights of scale
/// distance_scale_mm, the bumps' heights pulled towards none by field_stiffness. The
/// fields' Jacobian is taken to first order (each field's bumps at the point itself).
/// The fields' grid covers `mapped_surface`, the surface samples as `map` moves them.
/// `effective_dof` gets the fit's effective number of parameters at the end. The map's
/// rms_after_mm is left to the caller (it maps the samples anyway).
GlobalMap fit_shear_fields(GlobalMap map, const geometry::SignedDistance& distance,
                           const Eigen::Matrix3Xd& mapped_surface,
                           const std::vector<AttractivePoint>& points, const AffineFitOptions& o,
                           double& effective_dof);

/// An incompressible flow on top of `map` (all its other parts held), fitted as the shear
/// fields are (the same weights, stiffness and first-order Jacobian, v at the point itself).
/// Left out (an empty flow) when its dense Jacobian would exceed 5e7 entries (400 MB).
GlobalMap fit_flow(GlobalMap map, const geometry::SignedDistance& distance,
                   const Eigen::Matrix3Xd& mapped_surface,
                   const std::vector<AttractivePoint>& points, const AffineFitOptions& o,
                   double& effective_dof);
/// Distance (mm) of point p to the surface mapped by `map`, to first order:
/// D(q) / |grad_p D(q)|, q = M^-1 p, with the shears' Jacobian left out of the
/// normalisation (they are small). `b` is map.affine.a's inverse.
struct MappedDistance {
  double r;            ///< mm, positive outside
  Eigen::Vector3d q;   ///< M^-1 p, in the reference (mm)
  Eigen::Vector3d gp;  ///< gradient of D(M^-1 p) in p
  double nu;           ///< its length, at least 0.1
};
MappedDistance mapped_distance(const GlobalMap& map, const Eigen::Matrix3d& b,
                               const geometry::SignedDistance& distance, const Eigen::Vector3d& p);

}  // namespace organfit::fitting::detail
