#pragma once
// The global stage's solvers (module-internal; global_fit.h says what they fit and why):
// the whole-map Gauss-Newton by closest samples, the fits on the reference's signed
// distance (with and without the volume constraint), the shear fields' ridge fit, and
// the measures they and the choice among their fits (global_fit.cpp) share.
#include <Eigen/Cholesky>
#include <Eigen/Core>
#include <Eigen/LU>
#include <memory>
#include <vector>

#include "mapped_samples.h"
#include "organfit/fitting/global_fit.h"
#include "organfit/geometry/signed_distance.h"

namespace organfit::geometry {
class SampleGrid;
}

namespace organfit::fitting::detail {

/// The ridge system (J^T W J + lambda I) of a fit with more unknowns (n, J's columns) than
/// points (m, its rows) or fewer, factored in the smaller space: with fewer points (a
/// GTV's fields have ~500 heights for 20 to 87 points) by Woodbury's identity,
/// (lambda I + J^T W J)^-1 = (I - J^T W (lambda I + J J^T W)^-1 J) / lambda: m^3, not n^3;
/// with more (10,000 points), never an m x m matrix. There J^T W J is summed over the
/// rows' nonzeros alone (a point touches the bumps within 5.3 sigmas of it, a fifth of a
/// lung's 1,596 heights: the dense product took 31 GFLOP a step), a group of neighbouring
/// rows at a time (normal_matrix), and the symmetric positive definite matrix is factored
/// by Cholesky. Holds references to J and
/// w (m x n and m, w >= 0; lambda > 0). `row_order` (optional): the rows in an order in
/// which neighbours share most of their nonzeros (points sorted in space: spatial_order);
/// it only sets how the sum is grouped, not what it is.
class RidgeSystem {
 public:
  RidgeSystem(const Eigen::MatrixXd& jac, const Eigen::VectorXd& w, double lambda,
              const std::vector<int>* row_order = nullptr);
  /// (J^T W J + lambda I)^-1 g
  Eigen::VectorXd solve(const Eigen::VectorXd& g) const;
  /// Each point's leverage h_k = w_k J_k (J^T W J + lambda I)^-1 J_k^T (0 to 1), the diagonal
  /// of J (J^T W J + lambda I)^-1 J^T W: the share of its own residual a point's fit takes
  /// up. A point left out of the fit would have had the residual r_k / (1 - h_k) (to first
  /// order); their sum is the fit's effective number of unknowns.
  Eigen::VectorXd leverages() const;

 private:
  /// J^T W J + lambda I from the rows' nonzeros, on threads; its lower triangle.
  static Eigen::MatrixXd normal_matrix(const Eigen::MatrixXd& jac, const Eigen::VectorXd& w,
                                       double lambda, const std::vector<int>* row_order);
  const Eigen::MatrixXd& jac_;
  const Eigen::VectorXd& w_;
  double lambda_;
  bool in_points_;
  Eigen::PartialPivLU<Eigen::MatrixXd> lu_;  // in the points' space
  Eigen::LLT<Eigen::MatrixXd> llt_;          // in the unknowns' space
};

/// The points' indices in Z order (Morton order of their 1 mm cells): consecutive indices
/// lie close in space at every scale, so their rows of a local basis share their nonzeros.
std::vector<int> spatial_order(const std::vector<AttractivePoint>& points);

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

/// Each point's nearest surface sample as an affine map and quadratic shears move it, as a
/// grid over all the moved samples finds it (exact, ties to the lower index), without
/// moving them all: made once per surface, it moves only the samples about q = f^-1(p).
/// With D the distance from p to the image of q's nearest sample and e = |f(q) - p| (what
/// the computed inverse missed), every sample whose image lies within D of p lies within
/// L (D + e) + 2 slack of q, (L, slack) f^-1's stretch bound over the box about p of
/// half-width D + e (GlobalMap::inverse_stretch). Where the points' searches would examine
/// more samples than there are (many points, or one far off), every sample is moved and
/// gridded instead: the same answers. The fits' steps ask it once each with a few points:
/// moving and gridding a 1.5 L liver's 96,000 samples afresh at each of its some 270
/// steps took 0.5 s of the global stage's 0.8 s.
class MappedSampleSearch {
 public:
  explicit MappedSampleSearch(const Eigen::Matrix3Xd& samples);
  MappedSampleSearch(const MappedSampleSearch&) = delete;
  MappedSampleSearch& operator=(const MappedSampleSearch&) = delete;
  ~MappedSampleSearch();
  /// For the map f(s) = shears(a s + t) of `map`'s affine part and quadratic shears (its
  /// fields and flow left out) and each column k of p (mm): match[k] the nearest sample's
  /// index, r[k] the distance from p_k to its image (mm).
  void nearest(const GlobalMap& map, const Eigen::Matrix3Xd& p, std::vector<int>& match,
               std::vector<double>& r) const;

 private:
  const Eigen::Matrix3Xd& samples_;
  std::unique_ptr<geometry::SampleGrid> grid_;
};

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

/// What a part fitted on top of a map (fit_shear_fields, fit_flow) is judged by, at its fit's
/// end: its effective number of parameters (the leverages' sum) and each point's
/// residual had that point been left out of the part's fit, r_k / (1 - h_k) (mm; the
/// leverages of RidgeSystem::leverages), the map under it held.
struct LinearisedFit {
  double effective_dof = 0;
  std::vector<double> left_out_mm;
};

/// Smooth shear fields on top of `map` (its affine part and quadratic shears held): robust
/// Gauss-Newton on the points' mapped_distance, Geman-McClure weights of scale
/// distance_scale_mm, the bumps' heights pulled towards none by field_stiffness. The
/// fields' Jacobian is taken to first order (each field's bumps at the point itself).
/// The fields' grid covers `mapped_surface`, the surface samples as `map` moves them.
/// `judged` gets what the fit is judged by at its end (LinearisedFit). The map's
/// rms_after_mm is left to the caller (it maps the samples anyway).
GlobalMap fit_shear_fields(GlobalMap map, const geometry::SignedDistance& distance,
                           const Eigen::Matrix3Xd& mapped_surface,
                           const std::vector<AttractivePoint>& points, const AffineFitOptions& o,
                           LinearisedFit& judged);

/// An incompressible flow on top of `map` (all its other parts held), fitted as the shear
/// fields are (the same weights, stiffness and first-order Jacobian, v at the point itself).
/// Left out (an empty flow) when its dense Jacobian would exceed 5e7 entries (400 MB).
GlobalMap fit_flow(GlobalMap map, const geometry::SignedDistance& distance,
                   const Eigen::Matrix3Xd& mapped_surface,
                   const std::vector<AttractivePoint>& points, const AffineFitOptions& o,
                   LinearisedFit& judged);
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
