#pragma once
// What changes during a simulation: positions and velocities (OpenMM's State).
#include <Eigen/Core>

namespace organfit::particles {

/// Column i is particle i. Positions in mm (patient coordinates), velocities in mm/s.
using Positions = Eigen::Matrix3Xd;
using Velocities = Eigen::Matrix3Xd;
/// Column i is the total force on particle i (energy unit / mm).
using Forces = Eigen::Matrix3Xd;

struct State {
  Positions x;
  Velocities v;
  double time_s = 0.0;

  State() = default;
  explicit State(Positions positions) : x(std::move(positions)), v(Velocities::Zero(3, x.cols())) {}
  int size() const { return static_cast<int>(x.cols()); }
};

}  // namespace organfit::particles
