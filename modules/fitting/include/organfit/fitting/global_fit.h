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
#include "organfit/fitting/global_map.h"
#include "organfit/fitting/refill.h"
#include "organfit/fitting/surface_samples.h"
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
  /// points: the stiffer pull keeps bends from being taken for stretches, the softer one
  /// follows large stretches (numbers: docs/decisions.md, "The global fit's settings").
  double regularisation_alternative = 1e-3;
  double shear_regularisation = 1e-3;  ///< pull of the shears towards none, likewise
  /// fits whose mean square residual is within equally_good_dof / m of the best's (m
  /// points) explain the points equally well; fit_global_map keeps the one changing the
  /// shape least. Why over m: a fit with k more free parameters lowers the sum of squares
  /// by about k noise variances by chance alone, the mean square by k/m of itself; with
  /// 20 points a fit of the whole map "better" by 30% is still noise.
  double equally_good_dof = 20.0;
  /// the points' expected residual (mm; fit.residual_tolerance_mm): the noise scale of
  /// that window. Fits within dof / m of the noise's mean square of the best are equally
  /// good, the noise's mean square taken as the best's own, but never above this squared:
  /// a best fit far worse than the noise does not make every fit equally good (two points
  /// 8 mm off a cube: every candidate was). 0: the best's own, unbounded. Also the noise
  /// by which the kept map's change is shrunk (fit_global_map; 0: not shrunk).
  double noise_mm = 0.0;
  /// robust scale of the fit on the signed distance (mm): point k weighs
  /// (c^2 / (c^2 + r_k^2))^2 (Geman-McClure), c from 8x this down to it
  double distance_scale_mm = 2.0;
  /// with fewer points than the whole map's 21 unknowns (three shears), the fit on the signed
  /// distance also fits the shears twice: their pull as stated, and this many times it (0: only as
  /// stated): stiffer, a bend seen by few points is not taken for an affine change.
  double few_points_shear_stiffness = 10.0;
  /// ShearFields' width and spacing (mm; 0: no fields): the scale of the changes the
  /// global map follows beyond its quadratic shears, about the spacing of 20 to 50 points
  /// on half a prostate's surface; finer detail is the local stage's.
  double field_sigma_mm = 10.0;
  /// pull of the fields' heights towards none, sum_k w_k r_k^2 + this x |heights|^2 (mm^2
  /// per mm^2): a Gaussian prior on each height of 0.5 mm noise / sqrt(this).
  double field_stiffness = 0.3;
  /// IncompressibleFlow's node spacing (mm; 0: none): with it, the flow fitted on the same
  /// starts as the fields, at their stiffness matched to the flow (the same prior variance of
  /// a point's move), is a candidate too. For changes of shape no shear can make (a cube
  /// into a lung); off by default, since on sessions' changes it was chosen and did worse.
  double flow_sigma_mm = 0.0;
  double max_stretch = 1.5;  ///< a map stretching by more (or by less than 1/this) is refused
  /// ... and one whose quadratic shears, or whose shear fields, move any sample by more
  /// than this x the body's size (each on its own)
  double max_shear_mm = 0.25;
  /// ... and one moving the organ (its surface's mean displacement) by more than this (mm).
  /// Organs move between sessions by centimetres (setup error, breathing, filling); a fit
  /// that moves one by decimetres has points in other coordinates or units (a points file
  /// in cm put them 600 mm from a GTV, where a patch of its surface fitted them at 0.7 mm).
  double max_shift_mm = 100.0;
};

/// Robust ICP for x -> a x + t with det(a) = 1 matching the surface to the points:
/// point-to-plane (normals mapped by a^-T) plus a small point-to-point term, outliers
/// by a median + MAD rule, then det(a) = 1 by scaling at each iteration. The pull towards
/// the identity is annealed: 1000x `regularisation` first, tenfold less each time the fit
/// settles (or after `iterations` steps), down to `regularisation`.
AffineFit fit_volume_preserving_affine(const SurfaceSamples& surface,
                                       const std::vector<AttractivePoint>& points,
                                       const AffineFitOptions& options);

/// Fits the whole map jointly (Gauss-Newton, point-to-plane plus a small point-to-point
/// term, the same outlier rule), from two starts: the affine fit, and its translation
/// alone with the stiffness of both parts annealed from 1000x down (from the affine fit
/// alone a bend seen from one side is taken for a stretch and the shears stay in that
/// minimum); both with each pull towards the identity (regularisation and its
/// alternative). The shears are regularised towards none. Candidates: these fits, the
/// annealed start's map at the end of each stiffness level, and the affine fits.
///
/// With the organ's signed distance D at hand (`distance`, its zero level the organ's
/// surface), one more fit, free of closest-sample matches: robust Gauss-Newton from the
/// identity on each point's distance to the mapped surface, D(M^-1 p) / |grad_p D(M^-1 p)|, the
/// stiffness annealed as above and Geman-McClure weights whose scale falls with it (graduated
/// non-convexity, from 8x `distance_scale_mm`). Why: when a third of the points lie far off the
/// unmoved organ (a cube stretched 1.67x, its ends 10 mm out), a stiff fit by closest samples
/// matches the rest and the outlier rule then drops those points for good; the fits above reach
/// a 1.3x stretch at most and leave 3 to 4.5 mm of surface error. Its pulls are on the
/// change of shape (a, the shears) and on the displacement of the body's centre, as hard
/// per mm^2 as on a's entries: the organ stays where the reference has it unless the
/// points insist (freed, a stretch seen from one side is taken for a shift); the fits by
/// closest samples leave
/// the translation free, and a real shift is found by them. The fit from the identity is
/// made twice: each step solved freely and the map then rescaled to det 1 (which takes
/// back part of any stretch: stiffer along the stretch), and each step solved on the
/// linearised constraint tr(a^-1 da) = 0 (the least-squares volume-preserving step; two
/// points 8 mm beyond a 30 mm cube's faces, the paper's Fig. 8, are reached by the
/// second, 1.53x, while the first stops at 1.33x). Candidates are then judged
/// on D too (with fewer than 21 points, the distance fit is affine, and two more add
/// shears, as stated and held stiffer: few_points_shear_stiffness): the RMS over all points of
/// their distances capped at `distance_scale_mm` (judged over only the points each keeps, a fit
/// that drops a third of them looked as good as one that explains them).
///  * When the best fit of the points (robust RMS) stretches beyond max_stretch, or moves
///    the organ further than max_shift_mm, it is refused (the identity, marked so, with the
///    best fit's move and stretch): points that can only be explained by crushing the organ,
///    or by carrying it off, are not data to follow globally.
///  * Fits whose shears or fields are out of range (either moving the surface by more than
///    max_shear_mm x its size) are dropped; when that drops every fit of the whole map, the affine
///    part alone is what is left (marked shears_dropped); when nothing is left, refused.
///  * Of the rest, those within `equally_good_dof` / m of the best mean square (point-to-plane
///    RMS by the outlier rule; with `distance`, the capped RMS) explain the points equally well;
///    the one changing the shape least (surface displacement about its mean) is kept.
///  * With `distance` and field_sigma_mm > 0: ShearFields fitted on top of that map and of
///    the candidate changing the shape least of all (held; robust Gauss-Newton on the
///    distance, their heights pulled by field_stiffness) join the candidates, their mean
///    square raised by m / (m - k) for their k effective parameters (the trace of the
///    linearised fit's hat matrix: what they lower it by chance), and the choice above is
///    made again. Without the raise, fields fitted to the noise of 20 points put every
///    other fit out of the window. With `distance` and flow_sigma_mm > 0 (the fields on or
///    off), an IncompressibleFlow fitted likewise on the same two maps joins them too.
///  * With `distance` and noise_mm > 0, the kept map is moved towards the identity
///    (towards_identity) by the share of its change the points show beyond their noise
///    (positive-part James-Stein: 1 - (k - 2) noise^2 / the sum of squares it gained over the
///    identity, for its k free parameters; GlobalMap::kept_share): a fit that lowers the
///    residual of an unchanged organ below the noise has fitted the noise.
///
/// With `equally_good`, it is filled with the map returned and then every other fit in the
/// last choice's window: the fits the points cannot tell from it (emptied when refused).
GlobalMap fit_global_map(const SurfaceSamples& surface, const std::vector<AttractivePoint>& points,
                         const AffineFitOptions& options,
                         const geometry::SignedDistance* distance = nullptr,
                         std::vector<GlobalMap>* equally_good = nullptr);

}  // namespace organfit::fitting
