#pragma once
// Local stage of the "spread" fit: a smooth attractive force that moves a patch of
// skin around each point coherently, instead of pulling single particles into "tents".
//
// For point k with epicentre e_k (the skin particle whose surface is nearest, re-assigned
// when the skin is recomputed), the residual is the vector from that surface to p_k:
//     r_k = (|p_k - x_e| - rho) u_ek,   u_ek = (p_k - x_e) / |p_k - x_e|   (the balls'),
//     r_k = (n_e . (p_k - x_e - o_e)) n_e   (the organ's embedded surface: set_surface_feet,
// the tangent plane at the epicentre's foot x_e + o_e, normal n_e).
// Skin particles i of the patch (within patch_radius of e_k) share that displacement with
// Gaussian weights w_ik = exp(-|x_i - x_e|^2 / (2 sigma^2)) (positions at assignment),
// normalised where patches overlap (a partition of unity, so nearby points average
// rather than add):
//     F_i = kappa * sum_k w_ik r_k / max(1, sum_k w_ik),   |F_i| <= W(i) F_max / 2.
// Every force is proportional to the residuals, so it vanishes smoothly as the surface
// reaches the points (no chatter). Far outliers are rejected as in the paper's method,
// and so is a point whose residual disagrees with its neighbours' (a lone jump).
// Holding the volume: the patches' net outward push sum_i F_i . n_i is subtracted evenly
// over all skin particles (a uniform pressure), so the local stage reshapes the surface
// without inflating it (pulled skin otherwise opens gaps: +0.6 to +1.3% measured).
// Holding the pose: the term's net force F and torque T about the body's centroid c (the
// pulls and the pressure together) are taken back over every particle as a rigid motion's
// forces, F_i -= F / N + alpha x (x_i - c), alpha = J^-1 T, J = sum_i (|r_i|^2 I - r_i r_i^T):
// the term moves neither the body's centroid nor its turn. The organ's position and turn
// are the global stage's, chosen from every point by the stated noise; summed, the patches
// would re-decide them by patch weights (a small organ's patches cover much of its
// surface: a 55 cm3 GTV under an FEM bladder load moved 1.0 mm as a whole, away from the
// truth, where the global map had left it; docs/decisions.md).
#include <vector>

#include "organfit/fitting/attractive_points.h"
#include "organfit/fitting/skin.h"

namespace organfit::fitting {

struct SpreadForceParams {
  double stiffness_fraction = 0.3;  ///< kappa as a fraction of the LJ stiffness m n E0 / r0^2
  double patch_sigma_r0 = 1.5;      ///< Gaussian width of a patch, in r0
  double patch_radius_r0 = 3.5;     ///< bound of a patch, in r0
  double outlier_distance_mm = 0;   ///< reject points farther (0: half the model's diameter)
  /// A point whose signed residual disagrees with those of its nearest points by more
  /// than this many times their scatter (robust.h, normalised_median_test) is rejected:
  /// a lone point 5 mm off where its neighbours sit on the surface is not boundary data,
  /// while a dent shows in several neighbours at once. 0: no such test.
  double consistency_threshold = 3.0;
  int consistency_neighbours = 8;     ///< neighbours of a point for that test
  double consistency_noise_mm = 0.0;  ///< its epsilon, the residual noise (0: rho / 2)
  bool hold_volume = true;            ///< take the patches' net outward push back over the skin
  bool hold_pose = true;  ///< take the term's net force and torque back over the whole body
};

class SpreadAttractiveForce : public AttractivePointTerm {
 public:
  /// Throws std::invalid_argument on bad points or parameters (a stiffness <= 0, ...).
  SpreadAttractiveForce(std::vector<AttractivePoint> points, const particles::LennardJones& law,
                        double radius_mm, const SpreadForceParams& params, double skin_voxel_mm);

  std::string name() const override { return "attractive_points_spread"; }
  double add_forces(const particles::State& state, particles::Forces& f, bool want_energy) override;
  double stiffness() const override { return kappa_; }

  /// The organ's surface as each particle sees it (one column per particle; see
  /// fitting/embedded_body.h, surface_feet): a point's epicentre becomes the skin
  /// particle whose foot is nearest, and its residual its distance to that foot's
  /// tangent plane, so the surface fitted is the embedded body's, not the balls'.
  /// Throws std::invalid_argument on a non-finite offset or a normal not of unit length.
  void set_surface_feet(SurfaceFeet feet);

 private:
  void assign(const particles::Positions& x);
  /// Takes the term's net force and torque (its pulls, pull_, and the volume's `pressure`
  /// on the skin) back over every particle of `state` as a rigid motion's forces.
  void hold_pose(const particles::State& state, const Eigen::Vector3d& centroid, double pressure,
                 particles::Forces& f) const;
  double kappa_;
  SpreadForceParams params_;
  std::vector<std::vector<std::pair<int, double>>> patch_;  // (particle, weight) per point
  std::vector<std::vector<int>> neighbours_;  // each point's nearest points (fixed: points stay)
  SurfaceFeet feet_;                          // empty: the balls' surface
  std::vector<double> gap_;                   // each point's signed residual at assignment
  std::vector<int> in_patches_;  // the particles of any patch, ascending (set by assign)
  // The patches by particle: in_patches_[j]'s (point, weight) pairs are
  // pulls_[pull_first_[j] .. pull_first_[j + 1]), points ascending, so that each particle
  // sums its pulls on its own thread in the order a scan of the patches makes.
  std::vector<int> pull_first_;
  std::vector<std::pair<int, double>> pulls_;
  // Per step: each point's residual r_k (mm) and whether it pulls; each in_patches_[j]'s
  // pull F (energy / mm; 0 where no point pulls it), whose outward parts the volume's
  // pressure and whose sum and moment the pose's hold take back.
  std::vector<Eigen::Vector3d> residual_;
  std::vector<char> pulls_now_;
  std::vector<Eigen::Vector3d> pull_;
};

}  // namespace organfit::fitting
