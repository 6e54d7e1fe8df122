#pragma once
// What the particle model is (OpenMM's System): particles of one radius and mass, and
// the force terms acting on them. The changing positions and velocities live in State;
// time stepping lives in Integrator.
//
// Each force law is a small ForceTerm class (as LAMMPS keeps one pair style per class):
// CohesionForce (LJ between particles), SkeletonForce (shape keeping), and, in the
// fitting module, the attractive-point forces. Terms validate their input on creation.
#include <memory>
#include <string>
#include <vector>

#include "organfit/particles/cohesion.h"
#include "organfit/particles/state.h"

namespace organfit::particles {

class ForceTerm {
 public:
  virtual ~ForceTerm() = default;
  virtual std::string name() const = 0;
  /// Adds this term's forces to `f` (3 x N). Returns its potential energy when
  /// `want_energy`, else 0. A term may keep caches (neighbour lists) between calls,
  /// hence non-const. Velocity-dependent terms read state.v.
  virtual double add_forces(const State& state, Forces& f, bool want_energy) = 0;
  /// False for dissipative terms (damping): they have no potential energy.
  virtual bool conservative() const { return true; }
  /// The largest stiffness -dF/dr this term has in normal use (energy / mm^2); the
  /// integrator derives its time step from the stiffest term.
  virtual double stiffness() const { return 0.0; }
};

class Model {
 public:
  /// `radius_mm` is the particle radius rho = r0 / 2; `mass` in the model's mass unit.
  /// Throws std::invalid_argument on a non-positive radius or mass.
  Model(int particle_count, double mass, double radius_mm);

  int particle_count() const { return n_; }
  double mass() const { return mass_; }
  double radius_mm() const { return radius_mm_; }

  /// Adds a force term; the model owns it. Returns a reference for later use.
  template <class T>
  T& add(std::unique_ptr<T> term) {
    T& ref = *term;
    terms_.push_back(std::move(term));
    return ref;
  }
  const std::vector<std::unique_ptr<ForceTerm>>& terms() const { return terms_; }
  /// Removes a term (e.g. the attractive points after a fit). No-op if absent.
  void remove(const ForceTerm& term);

  /// Sets f to the sum of all terms' forces; returns the total potential energy
  /// when want_energy (else 0).
  double compute_forces(const State& state, Forces& f, bool want_energy);

  /// The largest stiffness of its terms (energy / mm^2), used for the time step.
  double stiffness() const;

 private:
  int n_;
  double mass_, radius_mm_;
  std::vector<std::unique_ptr<ForceTerm>> terms_;
};

}  // namespace organfit::particles
