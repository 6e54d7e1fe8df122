#pragma once
// Small systems shared by the physics-core tests.
#include <omp.h>

#include <random>

#include "organfit/particles/cohesion_force.h"
#include "organfit/particles/lattice_fill.h"
#include "organfit/particles/model.h"

namespace organfit::particles::testing {

/// N particles uniformly in a cube of side `side` (mm), no two closer than `min_gap`.
inline Positions random_cloud(int n, double side, double min_gap, unsigned seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> u(0, side);
  Positions x(3, n);
  for (int i = 0; i < n; ++i) {
    for (int tries = 0;; ++tries) {
      const Eigen::Vector3d p(u(rng), u(rng), u(rng));
      bool ok = true;
      for (int j = 0; j < i && ok; ++j)
        ok = (x.col(j) - p).norm() >= min_gap;
      if (ok || tries > 1000) {
        x.col(i) = p;
        break;
      }
    }
  }
  return x;
}

/// Potential energy by summing all pairs (the O(N^2) reference).
inline double all_pairs_energy(const LennardJones& law, const Positions& x) {
  double e = 0;
  for (int i = 0; i < x.cols(); ++i)
    for (int j = i + 1; j < x.cols(); ++j)
      e += law.energy((x.col(i) - x.col(j)).norm());
  return e;
}

/// Forces by summing all pairs.
inline Forces all_pairs_forces(const LennardJones& law, const Positions& x) {
  Forces f = Forces::Zero(3, x.cols());
  for (int i = 0; i < x.cols(); ++i)
    for (int j = i + 1; j < x.cols(); ++j) {
      const Eigen::Vector3d d = x.col(i) - x.col(j);
      const double r = d.norm();
      const Eigen::Vector3d fij = law.force(r) / r * d;
      f.col(i) += fij;
      f.col(j) -= fij;
    }
  return f;
}

/// A model with cohesion only.
inline Model cohesion_model(int n, const CohesionParams& p, double mass = 1.0,
                            double skin_r0 = 0.3) {
  Model model(n, mass, 0.5 * p.r0_mm);
  model.add(std::make_unique<CohesionForce>(LennardJones(p), skin_r0 * p.r0_mm));
  return model;
}

/// The largest difference between the positions `run(threads)` ends with on one thread and
/// on two (0: bitwise the same, as the thread count must not change a result).
template <class Run>
double one_and_two_threads_differ_by(Run&& run) {
  const int saved = omp_get_max_threads();
  Positions result[2];
  for (int t : {1, 2}) {
    omp_set_num_threads(t);
    result[t - 1] = run();
  }
  omp_set_num_threads(saved);
  return (result[0] - result[1]).cwiseAbs().maxCoeff();
}

}  // namespace organfit::particles::testing
