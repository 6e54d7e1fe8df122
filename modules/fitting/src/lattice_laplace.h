#pragma once
// The discrete Laplace equation on a lattice with held nodes (module-internal; the
// deformation's harmonic part, deformation.h): 6 u_i - sum of its 6 neighbours = 0 at
// every free node, the held nodes' values on the right-hand side. Solved by conjugate
// gradients preconditioned by a geometric multigrid V-cycle: plain conjugate gradients
// need iterations in proportion to the lattice's size (112 on a 2 L lung's 100-node
// lattice, several hundred on a million particles'), the V-cycle's a count set by the
// smoothing alone.
#include <Eigen/Core>
#include <array>
#include <vector>

namespace organfit::fitting::detail {

/// The free nodes of a lattice of `dims` nodes (x fastest): free_index[v] is node v's
/// free index, or -1 where it is held (every face node is held); free_nodes lists their
/// linear indices, ascending; neighbours[f] the free indices of free node f's 6
/// neighbours (-x, +x, -y, +y, -z, +z; -1 for a held one).
struct LatticeFreeNodes {
  Eigen::Vector3i dims = Eigen::Vector3i::Zero();
  std::vector<int> free_index;
  std::vector<long long> free_nodes;
  std::vector<std::array<int, 6>> neighbours;
};

/// The free nodes of a lattice of `dims` nodes: those not `held` and not on a face.
LatticeFreeNodes lattice_free_nodes(const Eigen::Vector3i& dims,
                                    const std::vector<std::uint8_t>& held);

/// Solves the equation for the three components of x (3 x free nodes) at once, in place
/// from the start in x, to |r| <= 1e-5 |rhs| per component (rhs: the held neighbours'
/// sums, 3 x free nodes). Returns the iterations taken (the most of the three).
int solve_lattice_laplace(const LatticeFreeNodes& lattice, const Eigen::Matrix3Xd& rhs,
                          Eigen::Matrix3Xd& x);

}  // namespace organfit::fitting::detail
