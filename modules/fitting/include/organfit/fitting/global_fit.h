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
#include "organfit/geometry/image_geometry.h"
#include "organfit/geometry/signed_distance.h"
#include "organfit/particles/state.h"

namespace organfit::fitting {

struct AffineFitOptions {
  int iterations = 60;
  double outlier_mads = 3.0;    ///< points beyond median + this x 1.4826 MAD get no weight
  double point_to_point = 0.1;  ///< weight of the point-to-point term beside point-to-plane
  /// pull of A towards I, relative to the points' spread
  double regularisation = 3e-3;
  /// a second pull also tried (0: none); fit_global_map keeps the better fit of the
  /// points. On a seeded sample of 240 cases of `organfit bench fit`, points on half the
  /// surface, 3e-3 alone kept bends from being taken for stretches (median surface
  /// distance 0.97 -> 0.91 mm against 1e-3 alone) but fell short on stretches (prostate
  /// stretched 1.4x: 0.51 -> 0.86 mm); each fits the points better where it is right.
  double regularisation_alternative = 1e-3;
  double shear_regularisation = 1e-3;  ///< pull of the shears towards none, likewise
  /// fits whose mean square residual is within equally_good_dof / m of the best's (m
  /// points) explain the points equally well; fit_global_map keeps the one changing the
  /// shape least. Why over m: a fit with k more free parameters lowers the sum of squares
  /// by about k noise variances by chance alone, the mean square by k/m of itself; with
  /// 20 points a fit of the whole map "better" by 30% is still noise. On the 225 target
  /// cases of `organfit bench fit --targets` (a fixed 10% before): median MSD 0.503 ->
  /// 0.471 mm, MSD <= 1 mm in 196 -> 202, HD95 <= 2.5 mm in 184 -> 192; of the 75 cases
  /// with 20 points 32 better by over 0.05 mm, 2 worse (9: 18 and 0; at 50 and 87 points
  /// a wash; 35: 200 and 189 within the targets).
  double equally_good_dof = 20.0;
  /// robust scale of the fit on the signed distance (mm): point k weighs
  /// (c^2 / (c^2 + r_k^2))^2 (Geman-McClure), c from 8x this down to it
  double distance_scale_mm = 2.0;
  /// with fewer points than the whole map's 21 unknowns, the fit on the signed distance
  /// also fits the shears, their pull this many times shear_regularisation (0: affine
  /// only). On the 75 target cases with 20 points of `organfit bench fit --targets`:
  /// median ratio of MSD to TPS's 0.56 -> 0.50; 11 cases better by over 0.05 mm, 3 worse
  /// (3x: 11 and 8; 30x: 5 and 2).
  double few_points_shear_stiffness = 10.0;
  double max_stretch = 1.5;  ///< a map stretching by more (or by less than 1/this) is refused
  double max_shear_mm =
      0.25;  ///< ... and one whose shears move any sample by more than this x the body's size
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

/// Surface samples of a reference body (a mask): one in `stride` boundary voxels (chosen
/// by a hash of the voxel's index: spread evenly over the surface, the same every run),
/// moved onto the zero level of the signed distance, with the distance's gradient as
/// normal. Denser and smoother than the particles' own surface.
SurfaceSamples reference_surface(const geometry::LabelVolume& reference, int stride = 1);
/// The same with the reference's signed distance already at hand (it is what costs).
SurfaceSamples reference_surface(const geometry::LabelVolume& reference,
                                 const geometry::SignedDistance& distance, int stride = 1);

/// Robust ICP for x -> a x + t with det(a) = 1 matching the surface to the points:
/// point-to-plane (normals mapped by a^-T) plus a small point-to-point term, outliers
/// by a median + MAD rule, then det(a) = 1 by scaling at each iteration. The pull towards
/// the identity is annealed: 1000x `regularisation` first, tenfold less each time the fit
/// settles (or after `iterations` steps), down to `regularisation`.
AffineFit fit_volume_preserving_affine(const SurfaceSamples& surface,
                                       const std::vector<AttractivePoint>& points,
                                       const AffineFitOptions& options);

/// Bending and twisting on top of the affine map: three shears applied in turn about
/// `centre` (u = q - centre),
///   x += c0 u_y^2 + c1 u_z^2 + c2 u_y u_z,
///   y += c3 u_x^2 + c4 u_z^2 + c5 u_x u_z,
///   z += c6 u_x^2 + c7 u_y^2 + c8 u_x u_y,
/// each moving one coordinate by a function of the other two: every shear, and so the
/// whole map, keeps volume exactly (Jacobian determinant 1), and inverts exactly.
struct QuadraticShears {
  Eigen::Vector3d centre = Eigen::Vector3d::Zero();
  Eigen::Matrix<double, 9, 1> c = Eigen::Matrix<double, 9, 1>::Zero();
  Eigen::Vector3d apply(const Eigen::Vector3d& q) const;
  Eigen::Vector3d inverse(const Eigen::Vector3d& q) const;
};

/// The global map: affine (det 1), then quadratic shears. Volume-preserving.
struct GlobalMap {
  AffineFit affine;
  QuadraticShears shears;
  double rms_after_mm = 0;      ///< point-to-surface over the kept points
  bool refused = false;         ///< no plausible map: the identity instead
  bool shears_dropped = false;  ///< the shears were implausible: the affine part alone
  /// which fit of fit_global_map's it is: "affine", "whole map", "whole map annealed",
  /// "signed distance", "signed distance (stiffer shears)" ("none": not fitted)
  const char* found_by = "none";
  Eigen::Vector3d apply(const Eigen::Vector3d& p) const {
    return shears.apply(affine.a * p + affine.t);
  }
  Eigen::Vector3d inverse(const Eigen::Vector3d& q) const;
};

/// The surface samples moved by `map`: points mapped, normals turned by the inverse
/// transpose of its Jacobian (by central differences) and made unit again.
SurfaceSamples map_surface(const GlobalMap& map, const SurfaceSamples& surface);

/// How much `map` changes the shape and orientation of the body whose surface is sampled
/// (mm): the RMS displacement of the samples about their mean displacement (the
/// translation).
double shape_change_mm(const GlobalMap& map, const SurfaceSamples& surface);

/// Fits the whole map jointly (Gauss-Newton, point-to-plane plus a small point-to-point
/// term, the same outlier rule), from two starts: the affine fit, and its translation
/// alone with the stiffness of both parts annealed from 1000x down (from the affine fit
/// alone a bend seen from one side is taken for a stretch and the shears stay in that
/// minimum); both with each pull towards the identity (regularisation and its
/// alternative). The shears are regularised towards none. Candidates: these fits, the
/// annealed start's map at the end of each stiffness level, and the affine fits.
///
/// With the reference's signed distance D at hand (`distance`), one more fit, free of
/// closest-sample matches: robust Gauss-Newton from the identity on each point's distance
/// to the mapped surface, D(M^-1 p) / |grad_p D(M^-1 p)|, the stiffness annealed as above
/// and Geman-McClure weights whose scale falls with it (graduated non-convexity, from 8x
/// `distance_scale_mm`). Why: when a third of the points lie far off the unmoved organ
/// (a cube stretched 1.67x, its ends 10 mm out), a stiff fit by closest samples matches
/// the rest and the outlier rule then drops those points for good; the fits above reach
/// a 1.3x stretch at most and leave 3 to 4.5 mm of surface error. Its pulls are on the
/// change of shape (a, the shears) and on the displacement of the body's centre, as hard
/// per mm^2 as on a's entries: the organ stays where the reference has it unless the
/// points insist (freed, a stretch seen from one side was taken for a shift: that cube
/// seen by 20 to 87 points, MSD 0.3-0.5 -> 1.1-3.8 mm); the fits by closest samples leave
/// the translation free, and a real shift is found by them. Candidates are then judged
/// on D too (with fewer than 21 points, the distance fit is affine, and a second
/// one adds shears held stiffer: few_points_shear_stiffness): the RMS over all points of their
/// distances capped at `distance_scale_mm` (judged over only the points each keeps, a fit that
/// drops a third of them looked as good as one that explains them).
///  * When the best fit of the points (robust RMS) stretches beyond max_stretch, it is
///    refused (the identity, marked so): points that can only be explained by crushing
///    the organ are not data to follow globally.
///  * Fits whose shears are out of range (moving the surface by more than max_shear_mm x
///    its size) are dropped; when that drops every fit of the whole map, the affine part
///    alone is what is left (marked shears_dropped); when nothing is left, refused.
///  * Of the rest, those within `equally_good_dof` / m of the best mean square (point-to-plane
///    RMS by the outlier rule; with `distance`, the capped RMS) explain the points equally well;
///    the one changing the shape least (surface displacement about its mean) is kept.
GlobalMap fit_global_map(const SurfaceSamples& surface, const std::vector<AttractivePoint>& points,
                         const AffineFitOptions& options,
                         const geometry::SignedDistance* distance = nullptr);

/// The model's reference body (the mask it was filled from) mapped by `map` and re-filled
/// with exactly `count` particles: the deepest sites of an fcc lattice of spacing
/// `a_nn_mm` inside the mapped body. Same count, same density: the same volume. The
/// reference, not the particles' own ball surface, is mapped: re-sampling the balls
/// would add a second discretisation error to the first.
particles::Positions refill_mapped_body(const geometry::LabelVolume& reference, int count,
                                        double a_nn_mm, const GlobalMap& map);

}  // namespace organfit::fitting
