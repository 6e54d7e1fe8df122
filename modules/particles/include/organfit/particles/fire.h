#pragma once
// FIRE, the fast inertial relaxation engine (Bitzek, Koskinen, Gaehler, Moseler & Gumbsch,
// Phys. Rev. Lett. 97, 170201, 2006; LAMMPS `min_style fire`): minimises the model's
// potential energy by motion whose velocity is turned towards the force,
//
//   v <- (1 - alpha) v + alpha |v| f / |f|,   then   v += dt f / M,   x += dt v,
//
// while the power P = f . v stays positive, the time step growing and alpha shrinking
// after `delay_steps` such steps; when P < 0 (it has gone past a minimum along its way)
// the velocities are zeroed, the time step halved and alpha reset (P = 0, at rest as at
// the start: a plain step). Damped dynamics, with its damping set for one pair, relaxes a
// body's slow collective modes (a surface layer settling over tens of particles)
// overdamped, over hundreds of steps; FIRE takes the largest stable step along them. Its
// constants are the paper's recommended ones, not tuned here.
#include <functional>

#include "organfit/particles/model.h"
#include "organfit/particles/state.h"

namespace organfit::particles {

struct FireOptions {
  double time_step_s = 0.0;       ///< the first step dt_start (s); > 0
  double max_time_step = 10.0;    ///< dt_max as a multiple of dt_start
  int delay_steps = 5;            ///< N_min: steps with P > 0 before dt grows
  double time_step_grow = 1.1;    ///< f_inc
  double time_step_shrink = 0.5;  ///< f_dec
  double alpha_start = 0.1;       ///< alpha at the start and after each P <= 0
  double alpha_shrink = 0.99;     ///< f_alpha
  double max_step_mm = 0.0;       ///< cap on one particle's move in one step (mm; 0: none)
};

struct FireResult {
  long long steps = 0;
  double rms_force = 0.0;  ///< sqrt(sum |f_i|^2 / n) at the end (energy / mm)
  bool settled = false;    ///< rms_force <= the tolerance
  long long capped_moves = 0;
};

/// Minimises from `state` (its velocities are the start's; zero at return) until the rms
/// force per particle is at most `rms_force_tolerance` (energy / mm) or `max_steps` steps
/// were taken. `after_step(step, rms_force)` (may be empty) is called after each step and
/// may return false to stop. Throws std::invalid_argument on bad options and
/// StabilityError (integrator.h) when the state becomes non-finite.
FireResult minimise_fire(Model& model, State& state, const FireOptions& options,
                         long long max_steps, double rms_force_tolerance,
                         const std::function<bool(long long, double)>& after_step = nullptr);

}  // namespace organfit::particles
