#include "organfit/particles/cohesion.h"

#include <cmath>
#include <string>

namespace organfit::particles {

double cohesion_r_min(int m, int n, double r0) {
  return r0 * std::pow(static_cast<double>(n + 1) / (m + 1), 1.0 / (n - m));
}

double cohesion_f_max(double E0, int m, int n, double r0) {
  const double s = r0 / cohesion_r_min(m, n, r0);  // (r0 / r_min)
  const double c = m * n * E0 / ((n - m) * r0);
  return std::abs(c * (ipow(s, n + 1) - ipow(s, m + 1)));
}

LennardJones::LennardJones(const CohesionParams& p) : p_(p) {
  auto bad = [](const std::string& what) { throw std::invalid_argument("cohesion: " + what); };
  if (!(p.E0 > 0) || !std::isfinite(p.E0)) bad("E0 must be > 0");
  if (!(p.r0_mm > 0) || !std::isfinite(p.r0_mm)) bad("r0 must be > 0 mm");
  if (p.m < 1) bad("m must be >= 1");
  if (p.n <= p.m)
    bad("n must be greater than m (got m=" + std::to_string(p.m) + ", n=" + std::to_string(p.n) +
        ")");
  if (p.n > 64) bad("n must be <= 64");
  if (!(p.floor_r0 > 0 && p.floor_r0 < 1)) bad("floor must be in (0, 1) r0");
  const double rmin = cohesion_r_min(p.m, p.n, 1.0);
  if (!(p.cutoff_r0 > rmin) || !std::isfinite(p.cutoff_r0)) {
    bad("cutoff must exceed r_min = " + std::to_string(rmin) + " r0, else nothing holds the body");
  }
  rc_ = p.cutoff_r0 * p.r0_mm;
  rf_ = p.floor_r0 * p.r0_mm;
  c_force_ = p.m * p.n * p.E0 / ((p.n - p.m) * p.r0_mm);
  e_shift_ = bare_energy(rc_);
  f_floor_ = bare_force(rf_);
  slope_floor_ = -bare_force_derivative(rf_);
  e_floor_ = bare_energy(rf_) - e_shift_;
}

double LennardJones::bare_force(double r) const {
  const double s = p_.r0_mm / r;
  return c_force_ * (ipow(s, p_.n + 1) - ipow(s, p_.m + 1));
}

double LennardJones::bare_force_derivative(double r) const {
  const double s = p_.r0_mm / r;
  return c_force_ / r * (-(p_.n + 1) * ipow(s, p_.n + 1) + (p_.m + 1) * ipow(s, p_.m + 1));
}

double LennardJones::bare_energy(double r) const {
  const double s = p_.r0_mm / r;
  return p_.E0 / (p_.n - p_.m) * (p_.m * ipow(s, p_.n) - p_.n * ipow(s, p_.m));
}

double LennardJones::force(double r) const {
  if (r >= rc_) return 0.0;
  if (r < rf_) return f_floor_ + slope_floor_ * (rf_ - r);
  return bare_force(r);
}

double LennardJones::energy(double r) const {
  if (r >= rc_) return 0.0;
  if (r < rf_) {
    const double d = rf_ - r;
    return e_floor_ + f_floor_ * d + 0.5 * slope_floor_ * d * d;
  }
  return bare_energy(r) - e_shift_;
}

}  // namespace organfit::particles
