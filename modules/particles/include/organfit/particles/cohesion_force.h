#pragma once
// CohesionForce: the Lennard-Jones cohesion of eq. 1-2 summed over neighbour pairs in
// O(N) (the paper's future-work item 2), with optional pairwise damping.
//
// Cost per particle and step: one gather and scatter of the positions, a displacement
// check, and ~1/2 * (4/3) pi (r_c + skin)^3 * density pair evaluations (Newton's third
// law). `organfit bench cohesion` measures it against LAMMPS.
#include <vector>

#include "organfit/particles/cohesion.h"
#include "organfit/particles/model.h"
#include "organfit/particles/neighbour_list.h"

namespace organfit::particles {

class CohesionForce : public ForceTerm {
 public:
  /// `skin_mm`: Verlet skin (default suggestion 0.3 r0). `pair_damping`: coefficient of
  /// the momentum-conserving dissipative force -gamma ((v_i - v_j).e_ij) e_ij between
  /// neighbours within the cutoff (mass unit / s); 0 disables it.
  CohesionForce(const LennardJones& law, double skin_mm, double pair_damping = 0.0);

  std::string name() const override { return "cohesion"; }
  double add_forces(const State& state, Forces& f, bool want_energy) override;
  double stiffness() const override { return law_.stiffness(); }

  const LennardJones& law() const { return law_; }
  const NeighbourList& neighbour_list() const { return list_; }
  double pair_damping() const { return pair_damping_; }
  /// Wall time in the pair loop, summed over calls (s): the "Pair" line of a LAMMPS
  /// timing breakdown (neighbour-list builds are in neighbour_list().build_seconds()).
  double pair_seconds() const { return pair_seconds_; }

 private:
  template <class Kernel, bool kDamped>
  double pair_loop(const Kernel& kernel, bool want_energy);

  LennardJones law_;
  NeighbourList list_;
  double pair_damping_;
  double pair_seconds_ = 0;
  std::vector<double> xs_, vs_, fs_, es_;  // sorted copies: positions, velocities, forces, energies
};

}  // namespace organfit::particles
