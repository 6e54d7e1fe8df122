#pragma once
// Attractive points (ultrasound data) and the paper's force towards them (s.3.2-3.3,
// eq. 5-6; METHOD.md s.5 and s.8).
#include <Eigen/Core>
#include <memory>
#include <utility>
#include <vector>

#include "organfit/fitting/skin.h"
#include "organfit/particles/model.h"

namespace organfit::geometry {
class SampleGrid;
}

namespace organfit::fitting {

struct AttractivePoint {
  Eigen::Vector3d p_mm;     ///< position, patient coordinates
  double confidence = 1.0;  ///< in (0, 1]: scales the point's force
};

/// W(i) for every particle: neighbours within `shell_mm` (the first shell), O(N).
std::vector<int> first_shell_counts(const particles::Positions& x, double shell_mm);

/// W(i) for the particles `of` (indices into x), one count per particle of x, 0 for the
/// others: the data terms need it only where their forces land, the skin. O(N) to bucket
/// the particles, then a few cells a listed particle.
std::vector<int> first_shell_counts(const particles::Positions& x, double shell_mm,
                                    const std::vector<int>& of);

/// The first shell of a relaxed fcc lattice, in r0: its 12 neighbours lie within this,
/// the next shell (at sqrt(2) times the spacing) beyond.
constexpr double kFirstShellR0 = 1.3;

/// Scales the data force on each particle down to at most W(i) F_max / 2 (paper s.3.3:
/// what a particle's neighbours can hold), so that however many points pull on one
/// particle, it is not torn off. `touched` lists the particles that got data forces.
void cap_by_cohesion(particles::Forces& data_force, const std::vector<int>& touched,
                     const std::vector<int>& w, double f_max);

/// The particle among `candidates` nearest to `p_mm`, and its squared distance (mm^2);
/// ties go to the first. {-1, infinity} when there are no candidates.
std::pair<int, double> nearest_particle(const particles::Positions& x,
                                        const std::vector<int>& candidates,
                                        const Eigen::Vector3d& p_mm);

/// The organ's surface as each particle sees it (fitting/embedded_body.h): its foot, the
/// nearest point of the surface, as an offset from the particle (mm), and the surface's
/// outward unit normal there. Near particle i the surface is the tangent plane through
/// x_i + offset_i; it moves with the particle. One column per particle.
struct SurfaceFeet {
  Eigen::Matrix3Xd offset_mm;
  Eigen::Matrix3Xd normal;
  bool empty() const { return offset_mm.cols() == 0; }
};

/// The particle among `candidates` whose surface lies nearest `p_mm`, and the signed
/// distance (mm, positive outside) from that surface to p:
///  * with `feet`: the particle with the shortest path from p through its foot,
///    |p - x_i - offset_i| + |offset_i| (of particles stacked under one foot, the outermost:
///    with the nearest foot alone a deeper one could take the pull, and on a model of
///    0.3 mm particles under 0.5 mm noise one was pulled out of the body), and p's distance
///    to that foot's tangent plane, n_i . (p - x_i - offset_i). A plane, not a sphere of
///    the foot's depth about the particle: the sphere falls away from the surface beside
///    the foot, so points on the surface would read as outside (by d^2 / 2 depth at a
///    distance d from the foot, 0.3 mm on average at the model's spacing) and be chased;
///  * without (feet empty): the least |p - x_i| - radius_mm, the balls' surface.
/// Ties go to the first. {-1, infinity} when there are no candidates.
std::pair<int, double> nearest_surface_particle(const particles::Positions& x,
                                                const std::vector<int>& candidates,
                                                const Eigen::Vector3d& p_mm,
                                                const SurfaceFeet& feet, double radius_mm);

/// The skin particles (`candidates` of x, and their feet when given) bucketed for the
/// queries of many points (geometry::SampleGrid): the same answers as the scans above,
/// ties included, at a cost set by the particles near each point rather than by the whole
/// skin (a 10,000-point fit of a million particles asked 10^9 distances a row by scans).
/// Holds references to x, candidates and feet: they must outlive it, unchanged.
class SkinIndex {
 public:
  SkinIndex(const particles::Positions& x, const std::vector<int>& candidates,
            const SurfaceFeet* feet = nullptr);
  ~SkinIndex();
  /// As nearest_particle(x, candidates, p_mm).
  std::pair<int, double> nearest_particle(const Eigen::Vector3d& p_mm) const;
  /// As nearest_surface_particle(x, candidates, p_mm, feet, radius_mm), feet as given here.
  std::pair<int, double> nearest_surface_particle(const Eigen::Vector3d& p_mm,
                                                  double radius_mm) const;
  /// The candidates within `radius_mm` of `centre_mm` (squared distance at most radius^2),
  /// in the order of `candidates`; replaces `out`.
  void within(const Eigen::Vector3d& centre_mm, double radius_mm, std::vector<int>& out) const;

 private:
  const particles::Positions& x_;
  const std::vector<int>& candidates_;
  const SurfaceFeet* feet_;
  Eigen::Matrix3Xd at_mm_, foot_at_mm_;  // the candidates' centres and feet
  std::unique_ptr<geometry::SampleGrid> centres_, feet_grid_;
};

/// Points farther than this from the skin are outliers unless a distance is given:
/// half the model's diameter (mm).
double default_outlier_distance(const particles::Positions& x);

/// Checks points on entry: finite coordinates, confidence in (0, 1]. Throws
/// std::invalid_argument naming the first bad point (index from 0).
void validate_points(const std::vector<AttractivePoint>& points);

/// What became of each point at the last evaluation.
struct PointStatus {
  int epicentre = -1;         ///< nearest skin particle
  double d_min_mm = 0;        ///< distance from the point to the nearest influenced centre
  bool inside_model = false;  ///< case 3: the point lies inside the body
  bool reached = false;       ///< case 2: d_min <= rho, no force
  bool rejected = false;      ///< an outlier: too far from the model to be fitted
  int influence_count = 0;
  double f_max_k = 0;  ///< force on the epicentre when the point was assigned
};

/// What the attractive forces (the paper's and ours) share: the points, the model's
/// radius rho, r0 and F_max (mm, mm, force units), its skin, each point's status at the
/// last evaluation, and W(i), each particle's first-shell count at the last assignment
/// (for the cap W(i) F_max / 2 of paper s.3.3).
class AttractivePointTerm : public particles::ForceTerm {
 public:
  bool conservative() const override { return false; }

  const std::vector<AttractivePoint>& points() const { return points_; }
  const std::vector<PointStatus>& status() const { return status_; }
  const SkinDetector& skin() const { return skin_; }
  double f_max() const { return f_max_; }

 protected:
  /// Throws std::invalid_argument on a bad point (validate_points).
  AttractivePointTerm(std::vector<AttractivePoint> points, const particles::LennardJones& law,
                      double radius_mm, double skin_voxel_mm, double first_shell_r0);
  /// W(i) at `x` of the skin's particles (the others' are 0: no data force lands on
  /// them): neighbours within first_shell_r0 r0.
  void count_first_shells(const particles::Positions& x);

  std::vector<AttractivePoint> points_;
  double rho_, r0_, f_max_;
  SkinDetector skin_;
  std::vector<PointStatus> status_;
  std::vector<int> w_;

 private:
  double first_shell_mm_;
};

struct PaperForceParams {
  double alpha = 2.0;                    ///< fall-off exponent alpha_k (> 1: falls off)
  double influence_radius_min_r0 = 1.2;  ///< influence radius at d_min = rho, in r0
  double influence_growth = 0.5;         ///< extra influence radius per mm of (d_min - rho)
  double influence_radius_max_r0 = 4.0;  ///< bound on the influence radius, in r0
  double total_force_factor = 3.0;       ///< a point's total force <= this x its F_max_k
  double outlier_distance_mm =
      0.0;  ///< reject points farther than this from the skin (0: 0.5 x model diameter)
  double first_shell_r0 = kFirstShellR0;  ///< W(i) counts neighbours within this distance
};

/// The paper's attractive force, with the fixes METHOD.md s.8 calls for:
///  * epicentre e_k: the skin particle nearest p_k; influence set: skin particles within
///    R_k = min(R_max, R_min + growth (d_min - rho)) of the epicentre (grows with the
///    distance, bounded);
///  * G_ik = K_k ((d_min - rho)/(r_ik - rho))^alpha (r_ik - rho) u_ik, pointing at p_k
///    in all three cases (one formula: outside pulls out, inside pushes in);
///  * K_k = F_max_k / (d_min - rho) (eq. 6) is fixed when the point is (re)assigned, at
///    each skin computation, and d_min is taken at every evaluation as the smallest
///    r_ik over the influence set, the ratio clamped at 1: the epicentre gets exactly
///    F_max_k on assignment and every force falls smoothly to zero as the set reaches
///    the point (with K_k recomputed every step the force is on/off and chatters);
///  * F_max_k = min(W(e_k) F_max / 2, F_max_k) with W counting the first shell of
///    neighbours (within 1.3 r0), times the point's confidence;
///  * the sum of a point's forces is capped at total_force_factor F_max_k (the others
///    are scaled down, the epicentre keeps its force); the sum of all points' forces on
///    one particle at W(i) F_max / 2 (many points on one particle); and points
///    farther than outlier_distance from the skin are rejected: a far outlier can
///    neither drag nor tear the body.
/// The paper's damping -K_a v is the integrator's (IntegratorOptions::damping).
class PaperAttractiveForce : public AttractivePointTerm {
 public:
  /// Throws std::invalid_argument on bad points or parameters (alpha < 1, ...).
  PaperAttractiveForce(std::vector<AttractivePoint> points, const particles::LennardJones& law,
                       double radius_mm, const PaperForceParams& params, double skin_voxel_mm);

  std::string name() const override { return "attractive_points_paper"; }
  double add_forces(const particles::State& state, particles::Forces& f, bool want_energy) override;

 private:
  void assign(const particles::Positions& x);
  PaperForceParams params_;
  std::vector<std::vector<int>> influence_;
  std::vector<double> k_;  // K_k of eq. 6
  particles::Forces g_;    // this term's forces, before the per-particle cap
  std::vector<int> touched_;
};

}  // namespace organfit::fitting
