#include "organfit/fitting/global_fit.h"

#include <Eigen/Dense>
#include <Eigen/SVD>
#include <algorithm>
#include <cmath>
#include <deque>
#include <limits>
#include <optional>

#include "global_solvers.h"
#include "mapped_samples.h"
#include "organfit/geometry/sample_grid.h"

namespace organfit::fitting {
namespace {

using detail::fit_flow;
using detail::fit_shear_fields;
using detail::fit_to_distance;
using detail::mapped_distance;
using detail::nearest_sample_rms;
using detail::refine_global_map;
using detail::robust_weights;

/// A global map as the window judges it: its surface samples mapped (kept for the plain
/// fits, the starts of the fitted parts; empty for a fitted part's), the points' capped RMS
/// against it (mm; a fitted part's raised by m / (m - k)), how much it changes the organ's
/// shape (mm, shape_change_of), and the effective parameters its fitted part (shear fields
/// or flow) adds to the affine part's and the shears' (0: none).
struct Candidate {
  const GlobalMap* map = nullptr;
  MappedSamples mapped;
  double rms_mm = 0;
  double change_mm = 0;
  double fitted_dof = 0;
};

/// The largest of a's principal stretches and their inverses (1: none).
double largest_stretch(const Eigen::Matrix3d& a) {
  const Eigen::Vector3d sv = Eigen::JacobiSVD<Eigen::Matrix3d>(a).singularValues();
  return std::max(sv[0], 1.0 / sv[2]);
}

/// Principal stretches within [1 / max_stretch, max_stretch].
bool within_stretch(const Eigen::Matrix3d& a, const AffineFitOptions& o) {
  return largest_stretch(a) <= o.max_stretch;
}

/// How far a map moves the organ (mm): its surface samples' mean displacement.
double organ_move_mm(const MappedSamples& mapped, const SurfaceSamples& surface) {
  if (surface.points.cols() == 0) return 0;
  return (mapped.full - surface.points).rowwise().mean().norm();
}

/// Stretches within bounds, and none of the quadratic shears, the shear fields and the flow
/// moving any surface sample by more than max_shear_mm x the body's size. Each has its own
/// bound: a 38-degree twist of the 30 mm cube moves its corners 14 mm by the shears, and
/// the fields' dent on top of that was refused when they shared one.
bool plausible(const GlobalMap& map, const MappedSamples& mapped, const SurfaceSamples& surface,
               const AffineFitOptions& o) {
  const double size =
      (surface.points.rowwise().maxCoeff() - surface.points.rowwise().minCoeff()).norm();
  const LargestMoves& moves = mapped.moves;
  return within_stretch(map.affine.a, o) && moves.shears_mm <= o.max_shear_mm * size &&
         moves.fields_mm <= o.max_shear_mm * size && moves.flow_mm <= o.max_shear_mm * size &&
         organ_move_mm(mapped, surface) <= o.max_shift_mm;
}

/// Robust RMS (mm) of the points' distances to the tangent planes of their nearest mapped
/// surface samples (normals turned by the affine part), the same outlier rule as the
/// fits. Unlike the nearest-sample distance the fits report, it has no floor from the
/// samples' spacing (0.4 to 0.6 mm on a CT mask, as much as the noise): fits that differ
/// by less than the noise can be told apart.
double point_to_plane_rms(const GlobalMap& map, const MappedSamples& mapped,
                          const SurfaceSamples& surface, const std::vector<AttractivePoint>& points,
                          double mads) {
  const Eigen::Matrix3Xd& moved = mapped.full;
  const Eigen::Matrix3d normal_map = map.affine.a.inverse().transpose();
  std::vector<double> r(points.size()), w;
  const geometry::SampleGrid grid(moved, geometry::SampleGrid::surface_cell_mm(moved));
  const auto m = static_cast<long long>(points.size());
#pragma omp parallel for schedule(static)
  for (long long k = 0; k < m; ++k) {
    const Eigen::Vector3d& p = points[static_cast<size_t>(k)].p_mm;
    const int j = grid.nearest(p).first;
    r[static_cast<size_t>(k)] =
        std::abs((normal_map * surface.normals.col(j)).normalized().dot(p - moved.col(j)));
  }
  return robust_weights(r, points, mads, w);
}

/// RMS (mm) over all points of residuals r (mm, one a point, by their confidences), each
/// capped at `cap_mm`: a fixed robust loss, so that fits which explain more of the points
/// are not judged on fewer.
template <class Residual>
double truncated_rms_of(const std::vector<AttractivePoint>& points, double cap_mm,
                        Residual&& r_of) {
  double sum = 0, weight = 0;
  for (size_t k = 0; k < points.size(); ++k) {
    const double r = std::min(std::abs(r_of(k)), cap_mm);
    sum += points[k].confidence * r * r, weight += points[k].confidence;
  }
  return std::sqrt(sum / std::max(weight, 1e-12));
}

/// truncated_rms_of the points' mapped_distance under `map`.
double truncated_rms(const GlobalMap& map, const geometry::SignedDistance& distance,
                     const std::vector<AttractivePoint>& points, double cap_mm) {
  const Eigen::Matrix3d b = map.affine.a.inverse();
  return truncated_rms_of(points, cap_mm, [&](size_t k) {
    return mapped_distance(map, b, distance, points[k].p_mm).r;
  });
}

}  // namespace

GlobalMap fit_global_map(const SurfaceSamples& surface, const std::vector<AttractivePoint>& points,
                         const AffineFitOptions& o, const geometry::SignedDistance* distance,
                         std::vector<GlobalMap>* equally_good) {
  if (equally_good) equally_good->clear();
  // Each pull towards the identity (the stated one, and the alternative if any) gives an
  // affine fit and, with enough points, fits of the whole map from two starts.
  std::vector<AffineFitOptions> pulls = {o};
  if (o.regularisation_alternative > 0 && o.regularisation_alternative != o.regularisation) {
    pulls.push_back(o);
    pulls.back().regularisation = o.regularisation_alternative;
  }
  // The pulls' fits are independent and mostly serial (small systems): one pull a thread,
  // each pull's fits kept in its own place and joined in the pulls' order.
  std::vector<std::vector<GlobalMap>> affine_of(pulls.size()), whole_of(pulls.size());
  const int pull_count = static_cast<int>(pulls.size());
#pragma omp parallel for schedule(static, 1) if (pull_count > 1)
  for (int k = 0; k < pull_count; ++k) {
    const AffineFitOptions& pull = pulls[static_cast<size_t>(k)];
    GlobalMap affine_only;
    affine_only.affine = fit_volume_preserving_affine(surface, points, pull);
    affine_only.rms_after_mm = affine_only.affine.rms_after_mm;
    affine_only.found_by = "affine";
    affine_of[static_cast<size_t>(k)].push_back(affine_only);
    if (points.size() < 21 || surface.points.cols() == 0) continue;  // 21 unknowns (c0..c8)
    // Two starts: from the affine fit, and from its translation alone with the stiffness
    // annealed (each level's settled map kept). From the affine fit alone, a bend seen
    // from one side can be taken for a stretch and the shears stay in that minimum; from
    // the translation, a large stretch can be missed.
    GlobalMap from_affine = affine_only;
    from_affine.shears.centre =
        ((affine_only.affine.a * surface.points).colwise() + affine_only.affine.t).rowwise().mean();
    GlobalMap from_translation = from_affine;
    const Eigen::Vector3d centroid = surface.points.rowwise().mean();
    from_translation.affine.t += affine_only.affine.a * centroid - centroid;
    from_translation.affine.a.setIdentity();
    for (bool anneal : {false, true})
      for (GlobalMap& fit : refine_global_map(anneal ? from_translation : from_affine, surface,
                                              points, pull, anneal)) {
        fit.found_by = anneal ? "whole map annealed" : "whole map";
        whole_of[static_cast<size_t>(k)].push_back(fit);
      }
  }
  std::vector<GlobalMap> affine_fits, fits;
  for (int k = 0; k < pull_count; ++k) {
    for (const GlobalMap& fit : affine_of[static_cast<size_t>(k)])
      affine_fits.push_back(fit);
    for (const GlobalMap& fit : whole_of[static_cast<size_t>(k)])
      fits.push_back(fit);
  }
  if (distance && !points.empty() && surface.points.cols() > 0) {
    GlobalMap identity;
    identity.shears.centre = surface.points.rowwise().mean();
    const bool with_shears = points.size() >= 21;
    for (const bool on_constraint : {false, true})
      for (GlobalMap& fit :
           fit_to_distance(identity, *distance, surface, points, o, with_shears, on_constraint)) {
        fit.found_by = on_constraint ? "signed distance on det 1" : "signed distance";
        (with_shears ? fits : affine_fits).push_back(fit);
      }
    // Fewer points than unknowns: the shears too, at the stated stiffness and held
    // stiffer. Either alone falls short: stiffer, a 10 mm bend was half followed (prostate
    // seen by 20 points: 1.90 mm) and taken for an affine change; at the stated stiffness
    // alone, stretches of 2 mm came out 0.3 to 0.4 mm worse. Both are candidates.
    if (!with_shears) {
      for (const double stiffness : {o.few_points_shear_stiffness, 1.0}) {
        if (!(stiffness > 0)) continue;
        AffineFitOptions held = o;
        held.shear_regularisation *= stiffness;
        for (GlobalMap& fit :
             fit_to_distance(identity, *distance, surface, points, held, true, false)) {
          fit.found_by =
              stiffness == 1.0 ? "signed distance (shears)" : "signed distance (stiffer shears)";
          fits.push_back(fit);
        }
      }
    }
  }
  // No plausible map: the identity, marked refused.
  auto refused = [rms = affine_fits[0].affine.rms_before_mm] {
    GlobalMap identity;
    identity.refused = true;
    identity.rms_after_mm = identity.affine.rms_after_mm = identity.affine.rms_before_mm = rms;
    return identity;
  };
  auto by_fit = [](const GlobalMap& l, const GlobalMap& r) {
    return l.rms_after_mm < r.rms_after_mm;
  };
  // The best fit of the points asks for a stretch or a move beyond the limits: refused,
  // whatever a worse fit within them would say.
  const std::vector<GlobalMap>& judged = fits.empty() ? affine_fits : fits;
  const GlobalMap& best_fit = *std::min_element(judged.begin(), judged.end(), by_fit);
  MappedSamples best_mapped = map_samples(best_fit, surface);  // judged again below
  const double best_move_mm = organ_move_mm(best_mapped, surface);
  auto refused_with_best = [&] {
    GlobalMap out = refused();
    out.refused_move_mm = best_move_mm;
    out.refused_stretch = largest_stretch(best_fit.affine.a);
    return out;
  };
  if (!within_stretch(best_fit.affine.a, o) || best_move_mm > o.max_shift_mm)
    return refused_with_best();
  // The plausible fits. Shears can swing out of range (a bulge seen from one side can do
  // that); when every fit of the whole map does, the affine part alone is what is left.
  std::vector<Candidate> candidates;
  auto keep_if_plausible = [&](const GlobalMap& fit) {
    MappedSamples m = &fit == &best_fit ? std::move(best_mapped) : map_samples(fit, surface);
    if (plausible(fit, m, surface, o)) candidates.push_back({&fit, std::move(m)});
  };
  for (const GlobalMap& fit : fits)
    keep_if_plausible(fit);
  const bool shears_dropped = !fits.empty() && candidates.empty();
  for (const GlobalMap& fit : affine_fits)
    keep_if_plausible(fit);
  if (candidates.empty()) return refused_with_best();
  // Points on part of the surface leave the rest free: fits from different starts and
  // stiffnesses often explain them equally well and differ by a millimetre elsewhere.
  // Of those within `equally_good_dof` / m of the noise's mean square of the best (the best's
  // own, at most noise_mm^2), the one changing the shape least is kept (the closest to
  // rest, as the pull towards the identity would choose).
  for (Candidate& c : candidates)
    c.rms_mm = distance ? truncated_rms(*c.map, *distance, points, o.distance_scale_mm)
                        : point_to_plane_rms(*c.map, c.mapped, surface, points, o.outlier_mads);
  auto least_rms = [&candidates] {
    return std::min_element(
               candidates.begin(), candidates.end(),
               [](const Candidate& l, const Candidate& r) { return l.rms_mm < r.rms_mm; })
        ->rms_mm;
  };
  // Every candidate with every point beyond the cap: the capped measure cannot rank them,
  // the uncapped one does.
  const bool saturated = distance && least_rms() >= o.distance_scale_mm * (1 - 1e-9);
  const double cap_mm = saturated ? std::numeric_limits<double>::infinity() : o.distance_scale_mm;
  if (saturated)
    for (Candidate& c : candidates)
      c.rms_mm = truncated_rms(*c.map, *distance, points, cap_mm);
  for (Candidate& c : candidates)
    c.change_mm = shape_change_of(c.mapped.full, surface.points);
  // Equally good: within `window` of the best mean square (of the noise's, at most noise2).
  const double window = o.equally_good_dof / static_cast<double>(points.size());
  const double noise2 =
      o.noise_mm > 0 ? o.noise_mm * o.noise_mm : std::numeric_limits<double>::infinity();
  // Which fits are within `window` of the best (by their mean squares rms^2).
  auto in_window = [&] {
    const double best = least_rms();
    std::vector<char> in(candidates.size());
    for (size_t c = 0; c < candidates.size(); ++c)
      in[c] = candidates[c].rms_mm * candidates[c].rms_mm <=
              best * best + window * std::min(best * best, noise2);
    return in;
  };
  // Of those, the one changing the shape least.
  auto least_change_in_window = [&] {
    const std::vector<char> in = in_window();
    size_t chosen = 0;
    double least = std::numeric_limits<double>::infinity();
    for (size_t c = 0; c < in.size(); ++c)
      if (in[c] && candidates[c].change_mm < least) least = candidates[c].change_mm, chosen = c;
    return chosen;
  };
  // candidates[pick], and with `equally_good` it and then every other fit in the window.
  // Each with the points' RMS before any fit (the identity's, the same for every fit).
  const double rms_before_mm = affine_fits[0].affine.rms_before_mm;
  // The chosen map moved towards the identity by the share of its change the points show
  // beyond their noise: positive-part James-Stein shrinkage. A least-squares fit of k
  // parameters to m points of noise variance s^2 lowers their sum of squares by about
  // k s^2 by chance alone; what it lowers beyond that is the change:
  //   kept = 1 - (k - 2) s^2 / (RSS_identity - RSS_fit), within [0, 1],
  // s the stated noise (noise_mm), k the map's free parameters (the affine part's 11, the
  // shears' 15 where it has them, the fields' or flow's effective count from their ridge
  // system), at most m; the sums uncapped, over the points the fit keeps (the outlier rule
  // on its residuals): a point far off weighs in neither, a large change is not taken for a
  // small one. A 20-point fit to an unchanged organ keeps little of itself, an 87-point fit
  // to a 5 mm stretch about 97%.
  const Eigen::Vector3d centre = surface.points.rowwise().mean();
  auto kept_share = [&](const GlobalMap& fit, double extra_dof) {
    if (!distance || !(o.noise_mm > 0)) return 1.0;
    const size_t count = points.size();
    std::vector<double> before(count), after(count), w;
    const Eigen::Matrix3d b = fit.affine.a.inverse();
    for (size_t k = 0; k < count; ++k) {
      before[k] = std::abs(
          mapped_distance(GlobalMap{}, Eigen::Matrix3d::Identity(), *distance, points[k].p_mm).r);
      after[k] = std::abs(mapped_distance(fit, b, *distance, points[k].p_mm).r);
    }
    robust_weights(after, points, o.outlier_mads, w);
    double m = 0, gained = 0;
    for (size_t k = 0; k < count; ++k)
      m += w[k], gained += w[k] * (before[k] * before[k] - after[k] * after[k]);
    const double k =
        std::min(m, 11.0 + (fit.shears.c.isZero(0) ? 0.0 : QuadraticShears::kCount) + extra_dof);
    if (!std::isfinite(gained)) return 1.0;  // no measure of it: the fit as chosen
    if (!(gained > 0)) return 0.0;           // the organ as it was explains them as well
    return std::clamp(1 - (k - 2) * noise2 / gained, 0.0, 1.0);
  };
  auto taken = [&](size_t pick) {
    const double share = kept_share(*candidates[pick].map, candidates[pick].fitted_dof);
    auto shrunk = [&](const GlobalMap& fit) {
      GlobalMap s = towards_identity(fit, share, centre);
      s.kept_share = share;
      s.shears_dropped = shears_dropped;
      s.affine.rms_before_mm = rms_before_mm;
      if (share < 1)
        s.rms_after_mm = s.affine.rms_after_mm =
            nearest_sample_rms(map_samples(s, surface), points, o.outlier_mads);
      return s;
    };
    GlobalMap out = shrunk(*candidates[pick].map);
    if (equally_good) {
      const std::vector<char> in = in_window();
      equally_good->push_back(out);
      for (size_t c = 0; c < candidates.size(); ++c)
        if (c != pick && in[c]) equally_good->push_back(shrunk(*candidates[c].map));
    }
    return out;
  };
  const size_t chosen = least_change_in_window();
  if (!distance || (!(o.field_sigma_mm > 0) && !(o.flow_sigma_mm > 0))) return taken(chosen);
  // Shear fields on top of the chosen map and of the one changing the shape least of all
  // (often near the identity: a dent is a local change, not a global one), each judged
  // with the rest. A fit with k effective parameters lowers the mean square by about k/m of
  // the noise's by chance alone, so theirs is raised by m / (m - k) first: without that,
  // fields that fitted the noise of 20 points (a mean square a quarter of the noise's)
  // put every fit without them out of the window. And a part on top of a start is tried
  // only where it foretells the points better than the start does: the points' residuals
  // had each been left out of the part's fit (LinearisedFit), in the same capped RMS,
  // below the start's. A change seen by one or two points is then left to the local stage:
  // a 1.5 L liver probed 5 mm, 87 points half over it, took fields of 56 effective
  // parameters which met those points at 0.33 mm, but foretold them left out at 0.82,
  // against 0.69 for the start; kept, they spread the dent (MSD 0.18 mm, 0.034 unmoved).
  const size_t least_of_all =
      static_cast<size_t>(std::min_element(candidates.begin(), candidates.end(),
                                           [](const Candidate& l, const Candidate& r) {
                                             return l.change_mm < r.change_mm;
                                           }) -
                          candidates.begin());
  std::deque<GlobalMap> refined;  // the candidates point into it: kept in place as it grows
  std::vector<size_t> starts = {chosen};
  if (least_of_all != chosen) starts.push_back(least_of_all);
  // With flow_sigma_mm, an incompressible flow on the same starts too, a candidate beside
  // the fields (not on by default: docs/decisions.md).
  candidates.reserve(candidates.size() + 2 * starts.size());  // a start stays in place
  for (const size_t c : starts)
    for (const bool as_flow : {false, true}) {
      if (!((as_flow ? o.flow_sigma_mm : o.field_sigma_mm) > 0)) continue;
      const Candidate& start = candidates[c];
      detail::LinearisedFit part;
      GlobalMap f =
          as_flow ? fit_flow(*start.map, *distance, start.mapped.full, points, o, part)
                  : fit_shear_fields(*start.map, *distance, start.mapped.full, points, o, part);
      if (as_flow ? f.flow.empty() : f.fields.empty()) continue;
      const double left_out_rms =
          truncated_rms_of(points, cap_mm, [&](size_t k) { return part.left_out_mm[k]; });
      if (!(left_out_rms < start.rms_mm)) continue;
      const MappedSamples m = map_samples(f, surface);
      if (!plausible(f, m, surface, o)) continue;
      const double dof = part.effective_dof;
      f.rms_after_mm = f.affine.rms_after_mm = nearest_sample_rms(m, points, o.outlier_mads);
      const double inflation = static_cast<double>(points.size()) /
                               std::max(1.0, static_cast<double>(points.size()) - dof);
      Candidate refit{&refined.emplace_back(std::move(f)), {}};  // its samples not kept
      refit.rms_mm = truncated_rms(*refit.map, *distance, points, cap_mm) * std::sqrt(inflation);
      refit.change_mm = shape_change_of(m.full, surface.points);
      refit.fitted_dof = dof;
      candidates.push_back(std::move(refit));
    }
  return taken(least_change_in_window());
}

}  // namespace organfit::fitting