#pragma once
// The Lennard-Jones cohesion law between two particles (paper eq. 1-4, METHOD.md s.2).
//
// Units: lengths in mm, energy E0 in the model's energy unit (mass unit * mm^2 / s^2),
// forces in energy / mm. All particles have one size ("mono-layer").
//
//   phi(r) = E0/(n-m) * ( m (r0/r)^n - n (r0/r)^m ),            phi(r0) = -E0
//   LJ(r)  = -phi'(r) = m n E0/((n-m) r0) * ((r0/r)^(n+1) - (r0/r)^(m+1))
//
// LJ(r) > 0 is repulsive (the paper prints the opposite sign for the direction vector).
// Two departures from the bare formula, both needed in practice:
//  * cutoff r_c: no force beyond it; the energy is shifted so phi(r_c) = 0, which keeps
//    E continuous (energy conservation) while F = -dE/dr holds for r < r_c;
//  * floor r_f: below it (r0/r)^(n+1) overflows or makes the system too stiff to
//    integrate, so LJ(r) is continued linearly with the slope at r_f. Force and energy
//    stay consistent (F = -dE/dr) and finite down to r = 0.
#include <stdexcept>

namespace organfit::particles {

struct CohesionParams {
  double E0 = 1.0;         ///< well depth (energy unit)
  double r0_mm = 1.0;      ///< equilibrium distance between two centres
  int m = 6;               ///< attractive exponent
  int n = 12;              ///< repulsive exponent, n > m
  double cutoff_r0 = 2.5;  ///< cutoff r_c in units of r0
  double floor_r0 = 0.5;   ///< linearisation floor r_f in units of r0, below r0
};

/// r_min: the distance of strongest attraction, r0 ((n+1)/(m+1))^(1/(n-m)) (eq. 3).
double cohesion_r_min(int m, int n, double r0);
/// F_max = |LJ(r_min)|: the largest pull cohesion resists (eq. 4).
double cohesion_f_max(double E0, int m, int n, double r0);

class LennardJones {
 public:
  /// Validates on creation (std::invalid_argument naming the bad parameter):
  /// E0 > 0, r0 > 0, 1 <= m < n <= 64, cutoff above r_min, 0 < floor < 1.
  explicit LennardJones(const CohesionParams& p);

  const CohesionParams& params() const { return p_; }
  double r0() const { return p_.r0_mm; }
  double cutoff() const { return rc_; }
  double floor_distance() const { return rf_; }
  double r_min() const { return cohesion_r_min(p_.m, p_.n, p_.r0_mm); }
  double f_max() const { return cohesion_f_max(p_.E0, p_.m, p_.n, p_.r0_mm); }
  /// Stiffness at r0, -LJ'(r0) = m n E0 / r0^2 (energy / mm^2).
  double stiffness() const { return p_.m * p_.n * p_.E0 / (p_.r0_mm * p_.r0_mm); }

  /// Pair force magnitude along the axis (+ repulsive), cutoff and floor applied.
  double force(double r) const;
  /// Pair energy, shifted to 0 at the cutoff, consistent with force().
  double energy(double r) const;
  /// The bare law of eq. 2 without cutoff or floor (for tests and plots).
  double bare_force(double r) const;
  double bare_energy(double r) const;
  /// Derivative of the bare force, LJ'(r).
  double bare_force_derivative(double r) const;

 private:
  CohesionParams p_;
  double rc_, rf_;
  double c_force_;                          // m n E0 / ((n-m) r0)
  double e_shift_;                          // bare_energy(rc)
  double f_floor_, slope_floor_, e_floor_;  // at r_f: force, -LJ'(r_f) > 0, shifted energy
};

/// Integer power by repeated squaring: exact exponents, no std::pow in hot loops.
inline double ipow(double x, int k) {
  double result = 1.0;
  while (k > 0) {
    if (k & 1) result *= x;
    x *= x;
    k >>= 1;
  }
  return result;
}

}  // namespace organfit::particles
