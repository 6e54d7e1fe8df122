#include "organfit/particles/model.h"

#include <algorithm>
#include <stdexcept>

namespace organfit::particles {

Model::Model(int particle_count, double mass, double radius_mm)
    : n_(particle_count), mass_(mass), radius_mm_(radius_mm) {
  if (particle_count < 0) throw std::invalid_argument("model: negative particle count");
  if (!(mass > 0)) throw std::invalid_argument("model: particle mass must be > 0");
  if (!(radius_mm > 0)) throw std::invalid_argument("model: particle radius must be > 0 mm");
}

void Model::remove(const ForceTerm& term) {
  terms_.erase(
      std::remove_if(terms_.begin(), terms_.end(), [&](const auto& t) { return t.get() == &term; }),
      terms_.end());
}

double Model::stiffness() const {
  double k = 0.0;
  for (const auto& term : terms_)
    k = std::max(k, term->stiffness());
  return k;
}

double Model::compute_forces(const State& state, Forces& f, bool want_energy) {
  f.setZero(3, state.size());
  double energy = 0.0;
  for (auto& term : terms_)
    energy += term->add_forces(state, f, want_energy);
  return energy;
}

}  // namespace organfit::particles
