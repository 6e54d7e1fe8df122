#pragma once
// Derivatives by central differences: a map's Jacobian where its parts' analytic ones
// are not at hand (map_surface turns normals by it) and the tests' checks of analytic
// gradients and of det = 1.
#include <Eigen/Core>

namespace organfit::fitting::detail {

/// The Jacobian of `map` (3-vector to 3-vector) at p: column c is
/// (map(p + h e_c) - map(p - h e_c)) / (2 h), h in mm.
template <class Map>
Eigen::Matrix3d central_jacobian(Map&& map, const Eigen::Vector3d& p, double h) {
  Eigen::Matrix3d jacobian;
  for (int c = 0; c < 3; ++c) {
    const Eigen::Vector3d e = h * Eigen::Vector3d::Unit(c);
    jacobian.col(c) = (map(p + e) - map(p - e)) / (2 * h);
  }
  return jacobian;
}

/// The gradient of a scalar `field` at p likewise.
template <class Field>
Eigen::Vector3d central_gradient(Field&& field, const Eigen::Vector3d& p, double h) {
  Eigen::Vector3d gradient;
  for (int c = 0; c < 3; ++c) {
    const Eigen::Vector3d e = h * Eigen::Vector3d::Unit(c);
    gradient(c) = (field(p + e) - field(p - e)) / (2 * h);
  }
  return gradient;
}

}  // namespace organfit::fitting::detail
