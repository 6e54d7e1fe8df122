#include "organfit/particles/fire.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <stdexcept>
#include <string>
#include <vector>

#include "capped_move.h"
#include "organfit/particles/integrator.h"
#include "organfit/particles/neighbour_list.h"

namespace organfit::particles {

namespace {

/// Sums of K per-particle terms over all particles, by fixed blocks of particles on threads
/// and the blocks' partial sums added in order: the same numbers for any thread count.
template <int K, class Term>
std::array<double, K> sums_by_blocks(int n, Term&& term) {
  constexpr int kBlock = 4096;
  const int blocks = (n + kBlock - 1) / kBlock;
  std::vector<std::array<double, K>> partial(static_cast<size_t>(blocks));
#pragma omp parallel for schedule(static) if (n >= kParallelMinParticles)
  for (int b = 0; b < blocks; ++b) {
    std::array<double, K> sum{};
    for (int i = b * kBlock; i < std::min(n, (b + 1) * kBlock); ++i) {
      const std::array<double, K> t = term(i);
      for (int k = 0; k < K; ++k)
        sum[k] += t[k];
    }
    partial[static_cast<size_t>(b)] = sum;
  }
  std::array<double, K> total{};
  for (const auto& p : partial)
    for (int k = 0; k < K; ++k)
      total[k] += p[k];
  return total;
}

}  // namespace

FireResult minimise_fire(Model& model, State& state, const FireOptions& options,
                         long long max_steps, double rms_force_tolerance,
                         const std::function<bool(long long, double)>& after_step) {
  auto bad = [](const std::string& what) { throw std::invalid_argument("fire: " + what); };
  if (!(options.time_step_s > 0) || !std::isfinite(options.time_step_s))
    bad("time step must be > 0 s");
  if (!(options.max_time_step >= 1)) bad("max_time_step must be >= 1 (a multiple of dt_start)");
  if (options.delay_steps < 0) bad("delay_steps must be >= 0");
  if (!(options.time_step_grow >= 1)) bad("time_step_grow must be >= 1");
  if (!(options.time_step_shrink > 0 && options.time_step_shrink < 1))
    bad("time_step_shrink must be in (0, 1)");
  if (!(options.alpha_start > 0 && options.alpha_start < 1)) bad("alpha_start must be in (0, 1)");
  if (!(options.alpha_shrink > 0 && options.alpha_shrink <= 1))
    bad("alpha_shrink must be in (0, 1]");
  if (!(options.max_step_mm >= 0)) bad("max_step_mm must be >= 0");
  if (!(rms_force_tolerance >= 0)) bad("the force tolerance must be >= 0");
  FireResult result;
  const int n = state.size();
  if (n == 0) {
    result.settled = true;
    return result;
  }
  const double inv_m = 1.0 / model.mass();
  const double dt_max = options.max_time_step * options.time_step_s;
  double dt = options.time_step_s, alpha = options.alpha_start;
  int since_negative = 0;
  Forces f;
  double f_sq = 0;
  auto measure_forces = [&] {  // f, |f|^2 summed and the rms force per particle
    model.compute_forces(state, f, false);
    f_sq = sums_by_blocks<1>(n, [&](int i) { return std::array{f.col(i).squaredNorm()}; })[0];
    result.rms_force = std::sqrt(f_sq / n);
  };
  measure_forces();
  for (long long step = 1; step <= max_steps && result.rms_force > rms_force_tolerance; ++step) {
    const auto [power, v_sq] = sums_by_blocks<2>(n, [&](int i) {
      return std::array{f.col(i).dot(state.v.col(i)), state.v.col(i).squaredNorm()};
    });
    // v <- keep v + turn f (then + dt f / M): the mixing, or v zeroed after a P < 0.
    double keep = 1, turn = 0;
    if (power > 0) {
      keep = 1 - alpha;
      turn = alpha * std::sqrt(v_sq / f_sq);
      if (++since_negative > options.delay_steps) {
        dt = std::min(dt * options.time_step_grow, dt_max);
        alpha *= options.alpha_shrink;
      }
    } else if (power < 0) {  // P = 0: at rest (the start), a plain step
      keep = 0;
      dt *= options.time_step_shrink;
      alpha = options.alpha_start;
      since_negative = 0;
    }
    const double kick = dt * inv_m;
    long long capped = 0;
    bool finite = true;
#pragma omp parallel for schedule(static) reduction(+ : capped) reduction(&& : finite) \
    if (n >= kParallelMinParticles)
    for (int i = 0; i < n; ++i) {
      auto v = state.v.col(i);
      v = keep * v + turn * f.col(i) + kick * f.col(i);
      if (detail::cap_move(v, dt, options.max_step_mm)) ++capped;
      state.x.col(i) += dt * v;
      finite = finite && state.x.col(i).allFinite();
    }
    result.capped_moves += capped;
    if (!finite)
      throw StabilityError("fire: the state became non-finite at step " + std::to_string(step) +
                           " (time step " + std::to_string(dt) + " s)");
    measure_forces();
    result.steps = step;
    if (!std::isfinite(result.rms_force))
      throw StabilityError("fire: the forces became non-finite at step " + std::to_string(step));
    if (after_step && !after_step(step, result.rms_force)) break;
  }
  state.v.setZero();
  result.settled = result.rms_force <= rms_force_tolerance;
  return result;
}

}  // namespace organfit::particles
