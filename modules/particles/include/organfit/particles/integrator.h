#pragma once
// Time stepping (OpenMM's Integrator): velocity Verlet, split as B A O A B.
//
//   B: v += dt/2 f/M      A: x += dt/2 v      O: v = c v + sqrt((1-c^2) kT/M) xi,
//   c = exp(-K_a dt / M)
//
// With no damping and no temperature, O is the identity and this is plain velocity
// Verlet (symplectic: energy checks). With K_a > 0 the O step applies the paper's
// damping -K_a v exactly (unconditionally stable, whatever K_a); with kT > 0 as well
// it is a Langevin thermostat (BAOAB, Leimkuhler & Matthews 2013), used to put the
// model in a fluid-like state. Noise is drawn from a counter-based generator keyed by
// (seed, step, particle), so results do not depend on the thread count.
//
// Stability: the time step defaults to `time_step_fraction * 2 sqrt(M/k)` with k the
// stiffest term's stiffness; a time step at or above 2 sqrt(M/k) (unstable even for
// one pair at r0) is refused on creation. Near the repulsion floor the stiffness is
// far above k, so each half-drift is capped at `max_step_r0 * r0 / 2`; the cap is
// counted. When it acts on more than 1% of the particles in one step (or anything
// becomes non-finite) the step is unstable: the state rolls back to the last checkpoint
// (taken every 10 steps) and the time step is halved; with adapt_time_step off, or
// after 12 halvings, a StabilityError is thrown instead. Never silent NaN.
#include <cstdint>
#include <functional>
#include <stdexcept>

#include "organfit/particles/model.h"

namespace organfit::particles {

/// The simulation could not continue stably (the message says why and where).
class StabilityError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

struct IntegratorOptions {
  double time_step_s = 0.0;         ///< 0: derived from the stiffness
  double time_step_fraction = 0.1;  ///< derived dt as a fraction of 2 sqrt(M/k)
  double damping = 0.0;             ///< K_a (mass unit / s): force -K_a v on every particle
  double temperature = 0.0;         ///< kT (energy unit); > 0 needs damping > 0
  std::uint64_t seed = 1;           ///< for the thermostat's noise
  double max_step_r0 = 0.2;         ///< cap on one step's displacement, in r0 (0: none)
  /// Speed limit (mm/s, 0: none). A displacement cap alone lets a particle keep far
  /// more kinetic energy than the well depth (an overlap stores thousands of E0) and
  /// tear the body; sqrt(2 * 5 E0 / M) keeps it whole (tested with (20,40) overlaps).
  double max_speed_mm_s = 0.0;
  double length_scale_mm = 1.0;  ///< r0 of the model, for the cap
  bool adapt_time_step = true;   ///< halve dt when the cap keeps acting; else throw
};

struct IntegratorStats {
  long long steps = 0;
  long long capped_moves = 0;  ///< particle half-drifts shortened by the cap
  int time_step_halvings = 0;
  double time_step_s = 0.0;  ///< current
};

class Integrator {
 public:
  /// Validates the options against the model (std::invalid_argument naming the option).
  Integrator(Model& model, const IntegratorOptions& options);

  /// 2 sqrt(M/k): the explicit scheme's limit for one pair at r0.
  static double stability_limit_s(const Model& model);

  /// Advances `steps` steps. `after_step(step_index)` may return false to stop early;
  /// after a rollback it is called again for the repeated step indices.
  void run(State& state, long long steps,
           const std::function<bool(long long)>& after_step = nullptr);

  /// Recomputes the cached forces (after force terms changed). Returns the potential.
  double refresh_forces(State& state, bool want_energy = false);
  const Forces& forces() const { return f_; }
  double kinetic_energy(const State& state) const;
  double time_step_s() const { return stats_.time_step_s; }
  /// The cap on one particle's move in one step (mm; 0: none): max_step_r0 r0, each
  /// half-drift taking half of it.
  double max_step_mm() const { return options_.max_step_r0 * options_.length_scale_mm; }
  const IntegratorStats& stats() const { return stats_; }
  const IntegratorOptions& options() const { return options_; }

 private:
  void drift_half(State& state, double dt, long long& capped);
  Model& model_;
  IntegratorOptions options_;
  IntegratorStats stats_;
  Forces f_;
  bool forces_ready_ = false;
};

struct RelaxResult {
  long long steps = 0;
  double kinetic_energy_per_particle = 0.0;
  bool settled = false;
};

/// Damped relaxation: runs until the kinetic energy per particle falls below
/// `ke_tolerance` (checked at every step after the first 20: a sum over the velocities,
/// small beside a step's forces) or `max_steps` pass.
RelaxResult relax(Model& model, State& state, const IntegratorOptions& options, long long max_steps,
                  double ke_tolerance);

}  // namespace organfit::particles
