#include "organfit/particles/integrator.h"

#include <cmath>
#include <string>

#include "capped_move.h"
#include "organfit/geometry/counter_random.h"
#include "organfit/particles/neighbour_list.h"

namespace organfit::particles {
namespace {

// A counter-based generator (geometry/counter_random.h), so noise is independent of
// thread order.
using geometry::splitmix64;
using geometry::uniform01;

/// Standard normal from (seed, step, particle, component) via Box-Muller.
double normal(std::uint64_t seed, long long step, int i, int d) {
  const std::uint64_t key =
      splitmix64(seed ^ splitmix64(static_cast<std::uint64_t>(step) * 0x100000001b3ULL + i)) +
      2 * d;
  const double u1 = uniform01(key), u2 = uniform01(key + 1);
  return std::sqrt(-2.0 * std::log(u1)) * std::cos(2 * M_PI * u2);
}

// A step is unstable when the cap shortened the moves of more than this fraction of the
// particles (and more than a few: one close pair may legitimately be capped).
constexpr double kCapFractionUnstable = 0.01;
constexpr int kCapCountTolerated = 4;
// State is checkpointed this often; an unstable step rolls back to the checkpoint.
constexpr int kCheckpointSteps = 10;
constexpr int kMaxHalvings = 12;

}  // namespace

double Integrator::stability_limit_s(const Model& model) {
  const double k = model.stiffness();
  return k > 0 ? 2.0 * std::sqrt(model.mass() / k) : std::numeric_limits<double>::infinity();
}

Integrator::Integrator(Model& model, const IntegratorOptions& options)
    : model_(model), options_(options) {
  auto bad = [](const std::string& what) { throw std::invalid_argument("integrator: " + what); };
  if (!(options.damping >= 0) || !std::isfinite(options.damping)) bad("damping must be >= 0");
  if (!(options.temperature >= 0) || !std::isfinite(options.temperature))
    bad("temperature must be >= 0");
  if (options.temperature > 0 && options.damping <= 0)
    bad("a temperature needs damping > 0 (the thermostat's friction)");
  if (!(options.max_step_r0 >= 0)) bad("max_step_r0 must be >= 0");
  if (!(options.max_speed_mm_s >= 0)) bad("max_speed must be >= 0 mm/s");
  if (!(options.length_scale_mm > 0)) bad("length scale must be > 0 mm");
  const double limit = stability_limit_s(model);
  double dt = options.time_step_s;
  if (dt == 0.0) {
    if (!(options.time_step_fraction > 0 && options.time_step_fraction < 1))
      bad("time_step_fraction must be in (0, 1)");
    dt = std::isfinite(limit) ? options.time_step_fraction * limit : 1e-3;
  }
  if (!(dt > 0) || !std::isfinite(dt)) bad("time step must be > 0 s");
  if (dt >= limit) {
    bad("time step " + std::to_string(dt) +
        " s is at or beyond the stability limit 2 sqrt(M/k) = " + std::to_string(limit) + " s");
  }
  stats_.time_step_s = dt;
}

double Integrator::kinetic_energy(const State& state) const {
  return 0.5 * model_.mass() * state.v.squaredNorm();
}

double Integrator::refresh_forces(State& state, bool want_energy) {
  const double e = model_.compute_forces(state, f_, want_energy);
  forces_ready_ = true;
  return e;
}

void Integrator::drift_half(State& state, double dt, long long& capped) {
  const long n = state.size();
  double cap = max_step_mm() * 0.5;
  if (options_.max_speed_mm_s > 0) {
    const double speed_cap = options_.max_speed_mm_s * dt;
    cap = cap > 0 ? std::min(cap, speed_cap) : speed_cap;
  }
  long long c = 0;
#pragma omp parallel for schedule(static) reduction(+ : c) if (n >= kParallelMinParticles)
  for (long i = 0; i < n; ++i) {
    auto v = state.v.col(i);
    if (detail::cap_move(v, dt, cap)) ++c;
    state.x.col(i) += dt * v;
  }
  capped += c;
}

void Integrator::run(State& state, long long steps,
                     const std::function<bool(long long)>& after_step) {
  const int n = state.size();
  if (n == 0) return;
  if (!forces_ready_ || f_.cols() != n) refresh_forces(state);
  const double inv_m = 1.0 / model_.mass();
  const long long target = stats_.steps + steps;
  const long long allowed =
      std::max<long long>(kCapCountTolerated, std::llround(kCapFractionUnstable * n));
  State checkpoint = state;
  Forces checkpoint_f = f_;
  long long checkpoint_steps = stats_.steps;
  while (stats_.steps < target) {
    if ((stats_.steps - checkpoint_steps) >= kCheckpointSteps) {
      checkpoint = state;
      checkpoint_f = f_;
      checkpoint_steps = stats_.steps;
    }
    const double dt = stats_.time_step_s;
    const double half = 0.5 * dt;
    long long capped = 0;
    state.v += (half * inv_m) * f_;   // B
    drift_half(state, half, capped);  // A
    if (options_.damping > 0) {       // O: exact -K_a v (and Langevin noise if kT > 0)
      const double c = std::exp(-options_.damping * dt * inv_m);
      if (options_.temperature > 0) {
        const double sigma = std::sqrt((1 - c * c) * options_.temperature * inv_m);
        const long long step_id = stats_.steps;
#pragma omp parallel for schedule(static) if (n >= kParallelMinParticles)
        for (int i = 0; i < n; ++i)
          for (int d = 0; d < 3; ++d)
            state.v(d, i) = c * state.v(d, i) + sigma * normal(options_.seed, step_id, i, d);
      } else {
        state.v *= c;
      }
    }
    drift_half(state, half, capped);  // A
    model_.compute_forces(state, f_, false);
    state.v += (half * inv_m) * f_;  // B
    state.time_s += dt;
    ++stats_.steps;
    stats_.capped_moves += capped;

    const bool finite = std::isfinite(state.x.sum()) && std::isfinite(state.v.sum());
    if (!finite || capped > allowed) {
      const std::string why = !finite ? "the state became non-finite"
                                      : "the displacement cap acted on " + std::to_string(capped) +
                                            " of " + std::to_string(n) + " particles in one step";
      if (!options_.adapt_time_step || stats_.time_step_halvings >= kMaxHalvings) {
        throw StabilityError("unstable at step " + std::to_string(stats_.steps) + ": " + why +
                             " (time step " + std::to_string(dt) + " s); reduce the time step");
      }
      // Roll back to the checkpoint and retry with half the step.
      state = checkpoint;
      f_ = checkpoint_f;
      stats_.steps = checkpoint_steps;
      stats_.time_step_s *= 0.5;
      ++stats_.time_step_halvings;
      continue;
    }
    if (after_step && !after_step(stats_.steps)) break;
  }
}

RelaxResult relax(Model& model, State& state, const IntegratorOptions& options, long long max_steps,
                  double ke_tolerance) {
  Integrator integrator(model, options);
  RelaxResult result;
  const int n = std::max(1, state.size());
  integrator.run(state, max_steps, [&](long long step) {
    result.steps = step;
    if (step < 20) return true;
    result.kinetic_energy_per_particle = integrator.kinetic_energy(state) / n;
    result.settled = result.kinetic_energy_per_particle < ke_tolerance;
    return !result.settled;
  });
  result.kinetic_energy_per_particle = integrator.kinetic_energy(state) / n;
  result.settled = result.kinetic_energy_per_particle < ke_tolerance;
  return result;
}

}  // namespace organfit::particles
