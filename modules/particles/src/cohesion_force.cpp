#include "organfit/particles/cohesion_force.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <stdexcept>

namespace organfit::particles {
namespace {

// Kernels return LJ(r)/r from r^2 for r_f <= r < r_c, without std::pow:
//   LJ(r)/r = c/r0 * ((r0/r)^(n+2) - (r0/r)^(m+2)),  c = m n E0 / ((n-m) r0).
// With even m and n, both powers are integer powers of (r0/r)^2: no square root.

/// m = 6, n = 12 with compile-time powers: the same arithmetic as LAMMPS lj/cut.
struct Kernel612 {
  double k, r02;
  double operator()(double r2) const {
    const double s2 = r02 / r2;
    const double s4 = s2 * s2;
    const double s8 = s4 * s4;
    return k * (s8 * s4 * s2 - s8);
  }
};

/// Any even m, n.
struct KernelEven {
  double k, r02;
  int half_m2, half_n2;  // (m+2)/2, (n+2)/2
  double operator()(double r2) const {
    const double s2 = r02 / r2;
    return k * (ipow(s2, half_n2) - ipow(s2, half_m2));
  }
};

/// Any m, n (one square root per pair).
struct KernelAny {
  double k, r02;
  int m2, n2;  // m+2, n+2
  double operator()(double r2) const {
    const double s = std::sqrt(r02 / r2);
    return k * (ipow(s, n2) - ipow(s, m2));
  }
};

/// A unit vector from a pair of particle ids, antisymmetric in the pair: the direction
/// in which two exactly coincident particles are pushed apart. Deterministic.
Eigen::Vector3d coincident_direction(int i, int j) {
  const int a = std::min(i, j), b = std::max(i, j);
  std::uint64_t h = (static_cast<std::uint64_t>(a) << 32) ^ static_cast<std::uint64_t>(b);
  h ^= h >> 33;
  h *= 0xff51afd7ed558ccdULL;
  h ^= h >> 33;
  const double phi = (h & 0xffff) * (2 * M_PI / 65536.0);
  const double z = ((h >> 16) & 0xffff) / 32768.0 - 1.0;
  const double rho = std::sqrt(std::max(0.0, 1 - z * z));
  Eigen::Vector3d d(rho * std::cos(phi), rho * std::sin(phi), z);
  return i < j ? d : Eigen::Vector3d(-d);
}

}  // namespace

CohesionForce::CohesionForce(const LennardJones& law, double skin_mm, double pair_damping)
    : law_(law), list_(law.cutoff(), skin_mm), pair_damping_(pair_damping) {
  if (!(pair_damping >= 0) || !std::isfinite(pair_damping)) {
    throw std::invalid_argument("cohesion: pair damping must be >= 0");
  }
}

namespace {

/// Everything the pair loop of one block reads, by value (kept in registers).
struct PairArrays {
  const int* __restrict nb;
  const int* __restrict first;
  const int* __restrict order;
  const double* __restrict xs;
  const double* __restrict vs;
  double* __restrict fs;
  double* __restrict es;
};

/// Pair forces of the slots [s_begin, s_end), half list, Newton's third law.
///
/// Each slot's neighbours go in chunks through three passes: gather the separations,
/// evaluate the law for the whole chunk (a loop without branches, which the compiler
/// vectorises: a quarter of listed pairs lie in the skin, at random, so a branch on the
/// cutoff would be mispredicted often), then accumulate and scatter the forces in list
/// order. Pairs in the skin get an exact zero. Close pairs (below the floor, rare) are
/// redone with the linearised law.
template <class Kernel, bool kDamped>
void block_pairs(int s_begin, int s_end, const Kernel kernel, const PairArrays a, const double rc2,
                 const double rf2, const double eps, const double gamma, const LennardJones& law,
                 const bool want_energy) {
  constexpr int kChunk = 64;
  alignas(16) double dx[kChunk], dy[kChunk], dz[kChunk], r2[kChunk], fr[kChunk];
  for (int s = s_begin; s < s_end; ++s) {
    const double xi = a.xs[3 * s], yi = a.xs[3 * s + 1], zi = a.xs[3 * s + 2];
    double fxi = 0, fyi = 0, fzi = 0, ei = 0;
    const int kend = a.first[s + 1];
    for (int k0 = a.first[s]; k0 < kend; k0 += kChunk) {
      const int len = std::min(kChunk, kend - k0);
      const int* __restrict nb = a.nb + k0;
      bool close = false;
      for (int u = 0; u < len; ++u) {
        const int t = nb[u];
        dx[u] = xi - a.xs[3 * t], dy[u] = yi - a.xs[3 * t + 1], dz[u] = zi - a.xs[3 * t + 2];
        r2[u] = dx[u] * dx[u] + dy[u] * dy[u] + dz[u] * dz[u];
        close |= r2[u] < rf2;
      }
      // Vectorised only with -fno-trapping-math (set for this module): the law is then
      // evaluated for every pair and the select discards the skin pairs' values.
      for (int u = 0; u < len; ++u) {
        const double f = kernel(r2[u]);
        fr[u] = r2[u] < rc2 ? f : 0.0;
      }
      if (close) {
        for (int u = 0; u < len; ++u) {
          if (r2[u] >= rf2) continue;
          if (r2[u] < eps * eps) {  // coincident: a fixed direction
            const Eigen::Vector3d d = eps * coincident_direction(a.order[s], a.order[nb[u]]);
            dx[u] = d.x(), dy[u] = d.y(), dz[u] = d.z(), r2[u] = eps * eps;
          }
          const double r = std::sqrt(r2[u]);
          fr[u] = law.force(r) / r;
        }
      }
      for (int u = 0; u < len; ++u) {
        const int t = nb[u];
        double f = fr[u];
        if constexpr (kDamped) {
          // -gamma ((v_i - v_j) . e) e, with e = d / r: coefficient gamma (dv.d) / r^2.
          if (r2[u] < rc2) {
            const double dvd = (a.vs[3 * s] - a.vs[3 * t]) * dx[u] +
                               (a.vs[3 * s + 1] - a.vs[3 * t + 1]) * dy[u] +
                               (a.vs[3 * s + 2] - a.vs[3 * t + 2]) * dz[u];
            f -= gamma * dvd / r2[u];
          }
        }
        fxi += dx[u] * f;
        fyi += dy[u] * f;
        fzi += dz[u] * f;
        a.fs[3 * t] -= dx[u] * f;
        a.fs[3 * t + 1] -= dy[u] * f;
        a.fs[3 * t + 2] -= dz[u] * f;
        if (want_energy && r2[u] < rc2) ei += law.energy(std::sqrt(r2[u]));
      }
    }
    a.fs[3 * s] += fxi;
    a.fs[3 * s + 1] += fyi;
    a.fs[3 * s + 2] += fzi;
    if (want_energy) a.es[s] = ei;
  }
}

}  // namespace

template <class Kernel, bool kDamped>
double CohesionForce::pair_loop(const Kernel& kernel, bool want_energy) {
  const PairArrays arrays{list_.neighbours().data(),
                          list_.first().data(),
                          list_.order().data(),
                          xs_.data(),
                          vs_.data(),
                          fs_.data(),
                          es_.data()};
  const double rc2 = law_.cutoff() * law_.cutoff();
  const double rf2 = law_.floor_distance() * law_.floor_distance();
  const double eps = 1e-9 * law_.r0();
  const auto& block_begin = list_.block_begin();
  const auto& block_end = list_.block_end();
  const bool parallel = list_.size() >= kParallelMinParticles;
#pragma omp parallel if (parallel)
  {
    for (const auto& colour : list_.colours()) {
      const long blocks = static_cast<long>(colour.size());
#pragma omp for schedule(dynamic, 1)
      for (long bi = 0; bi < blocks; ++bi) {
        const int b = colour[bi];
        block_pairs<Kernel, kDamped>(block_begin[b], block_end[b], kernel, arrays, rc2, rf2, eps,
                                     pair_damping_, law_, want_energy);
      }
    }
  }
  double energy = 0;
  if (want_energy)
    for (double e : es_)
      energy += e;  // serial: the same order for any thread count
  return energy;
}

double CohesionForce::add_forces(const State& state, Forces& f, bool want_energy) {
  const int n = state.size();
  if (n < 2) return 0.0;
  list_.update(state.x);
  const auto& order = list_.order();
  xs_.resize(3 * static_cast<size_t>(n));
  fs_.assign(3 * static_cast<size_t>(n), 0.0);
  if (want_energy) es_.assign(n, 0.0);
  const bool damped = pair_damping_ > 0;
  if (damped) vs_.resize(3 * static_cast<size_t>(n));
#pragma omp parallel for schedule(static) if (n >= kParallelMinParticles)
  for (int s = 0; s < n; ++s) {
    const int i = order[s];
    for (int d = 0; d < 3; ++d)
      xs_[3 * s + d] = state.x(d, i);
    if (damped)
      for (int d = 0; d < 3; ++d)
        vs_[3 * s + d] = state.v(d, i);
  }

  const auto& p = law_.params();
  const double k = p.m * p.n * p.E0 / ((p.n - p.m) * p.r0_mm) / p.r0_mm;
  const double r02 = p.r0_mm * p.r0_mm;
  double energy = 0;
  const auto start = std::chrono::steady_clock::now();
  auto run = [&](const auto& kernel) {
    energy = damped ? pair_loop<std::decay_t<decltype(kernel)>, true>(kernel, want_energy)
                    : pair_loop<std::decay_t<decltype(kernel)>, false>(kernel, want_energy);
  };
  if (p.m == 6 && p.n == 12) {
    run(Kernel612{k, r02});
  } else if (p.m % 2 == 0 && p.n % 2 == 0) {
    run(KernelEven{k, r02, (p.m + 2) / 2, (p.n + 2) / 2});
  } else {
    run(KernelAny{k, r02, p.m + 2, p.n + 2});
  }
  pair_seconds_ += std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();

#pragma omp parallel for schedule(static) if (n >= kParallelMinParticles)
  for (int s = 0; s < n; ++s) {
    const int i = order[s];
    for (int d = 0; d < 3; ++d)
      f(d, i) += fs_[3 * s + d];
  }
  return energy;
}

}  // namespace organfit::particles
