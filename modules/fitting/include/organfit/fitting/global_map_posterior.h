#pragma once
// How well the points fix the global map's affine part: a Laplace approximation of its
// posterior, and the spread it gives the surface (mm^2 along the surface's normal).
//
// The affine part x -> c' + A (x - c) (c the reference samples' centroid, c' its image; 12
// unknowns, on det A = 1: 11) moves a mapped sample x, normal nu, along its normal by
//   g(x)^T dtheta,   g(x) = (nu, nu (x - c)^T)   (dtheta = (dc', dA) row by row),
// and a point p, fitted at its nearest mapped sample x_p, sees that move in its residual,
// beside the local change there and its noise: the local change is the uncertainty's
// Gaussian process (surface_uncertainty.h: s^2 exp(-|a - b|^2 / 2 l^2)), so points closer
// than l see much the same local change and tell the map's move apart from it only
// together. With G the points' g(x_p) (rows), K that covariance among them and N their
// noise (n^2 over their confidence; outliers by the fit's rule left out), the information
// is F = G^T (K + N)^-1 G; the prior on dtheta is N(0, P^-1):
// dc' of sd tau a component and dA of sd tau / R an entry (R the samples' RMS distance
// from c: a turn or stretch moving the surface by about tau), and on det A = 1 (linearised:
// tr(A^-1 dA) = 0, a basis Z of that subspace) the posterior covariance is
//   S = Z (Z^T (F + P) Z)^-1 Z^T,   var(x) = g(x)^T S g(x).
// Where the points fix the map (spread over the organ), var is about n^2 k / m, under a
// tenth of a mm for 87 points; where they leave a move of the organ free (points on one
// line, or one plane such as a single 2D ultrasound frame, which a move across it and a
// stretch explain as well), var rises to the prior's tau^2 on the parts of the surface that
// move. The fit's chosen map is one of those; this says how far the others lie.
#include <Eigen/Core>
#include <vector>

#include "organfit/fitting/attractive_points.h"
#include "organfit/fitting/global_map.h"
#include "organfit/fitting/surface_samples.h"

namespace organfit::fitting {

struct GlobalMapPosterior {
  /// Each sample of `surface` as the map moves it (mm), and var(x) there (mm^2).
  Eigen::Matrix3Xd at_mm;
  Eigen::VectorXd variance_mm2;
};

/// `map` the kept global map, `surface` the reference samples (points mm, unit normals),
/// `points` the attractive points (mm), `noise_mm` n > 0, `motion_sd_mm` tau > 0,
/// `local_sd_mm` s > 0 and `local_length_mm` l > 0 the local change's prior, `mads` the fit's
/// outlier rule (global_fit.h). An empty surface or no points: the prior alone.
GlobalMapPosterior global_map_posterior(const GlobalMap& map, const SurfaceSamples& surface,
                                        const std::vector<AttractivePoint>& points, double noise_mm,
                                        double motion_sd_mm, double local_sd_mm,
                                        double local_length_mm, double mads);

}  // namespace organfit::fitting
