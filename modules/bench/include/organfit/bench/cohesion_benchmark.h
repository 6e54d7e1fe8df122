#pragma once
// `organfit bench cohesion`: the LAMMPS `bench/in.lj` system timed in organfit and, when
// Debian's `lmp` is installed, in LAMMPS in the same invocation.
//
// The system: fcc lattice at reduced density 0.8442, LJ 12-6 (sigma = epsilon = 1,
// i.e. r0 = 2^(1/6), E0 = 1) with cutoff 2.5 sigma, neighbour skin 0.3 sigma, velocities
// for T = 1.44, NVE velocity Verlet, dt = 0.005. Boundaries are open in both codes
// (LAMMPS `boundary s s s`), since organ models are not periodic; both hold exactly
// 4 c^3 atoms. organfit rebuilds its list when a particle moved skin/2 (never missing a
// pair). LAMMPS runs twice: as in.lj (`every 20 check no`, unconditional rebuilds:
// `ratio_vs_lammps`) and with organfit's policy (`every 1 check yes`:
// `ratio_vs_lammps_checked`). Timings cover the stepping loop only ("Loop time"); the
// pair loop and the list builds are also timed apart (`pair_us_per_particle_step`,
// `neighbour_us_per_particle_step`, LAMMPS's "Pair" and "Neigh" lines).
#include <nlohmann/json.hpp>
#include <string>

namespace organfit::bench {

struct CohesionBenchOptions {
  long long particles = 32000;  ///< rounded to 4 c^3 (whole fcc cells)
  long long steps = 100;
  int threads = 1;
  bool run_lammps = true;  ///< when `lmp` is on PATH
  std::string lammps_binary = "lmp";
};

/// Runs the benchmark; returns {particles, steps, threads, us_per_particle_step,
/// lammps_us_per_particle_step, ratio_vs_lammps, ...} (LAMMPS keys null when absent).
nlohmann::json run_cohesion_benchmark(const CohesionBenchOptions& options);

/// Per-particle-step cost from 1,000 to 1,000,000 particles (organfit only), with the
/// spread between 10,000 and 1,000,000.
nlohmann::json run_cohesion_scaling(int threads);

}  // namespace organfit::bench
