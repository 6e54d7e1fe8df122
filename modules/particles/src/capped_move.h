#pragma once
// The displacement cap both the integrator and FIRE step with: a safety net near the
// repulsion floor, where the stiffness is far above the one the time step was set for.
#include <Eigen/Core>

namespace organfit::particles::detail {

/// Shortens velocity `v` so that its move over `dt` is at most `cap_mm` (0: no cap);
/// true when it did (the kinetic energy it removes is the cap's doing, counted by callers).
template <class Velocity>
bool cap_move(Velocity&& v, double dt, double cap_mm) {
  if (!(cap_mm > 0)) return false;
  const double move = v.norm() * dt;
  if (!(move > cap_mm)) return false;
  v *= cap_mm / move;
  return true;
}

}  // namespace organfit::particles::detail
