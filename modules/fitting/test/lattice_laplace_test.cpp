// The deformation's harmonic part (src/lattice_laplace.h): the discrete Laplace equation
// on a lattice with held nodes, by multigrid-preconditioned conjugate gradients.
#include "../src/lattice_laplace.h"

#include <gtest/gtest.h>

#include <cmath>

namespace organfit::fitting::detail {
namespace {

// A linear field is discrete-harmonic: held at the faces and on an ellipsoidal body
// inside, the solution is the field itself at every free node (to the solver's 1e-5),
// and the preconditioned iteration needs a few tens of iterations on a lattice whose
// plain conjugate gradients need a hundred and more.
TEST(LatticeLaplace, ReproducesALinearFieldInFewIterations) {
  const Eigen::Vector3i dims(65, 49, 41);
  const long long nodes = 1LL * dims[0] * dims[1] * dims[2];
  std::vector<std::uint8_t> held(static_cast<size_t>(nodes), 0);
  auto at = [&](int i, int j, int k) { return i + 1LL * dims[0] * (j + 1LL * dims[1] * k); };
  for (int k = 0; k < dims[2]; ++k)
    for (int j = 0; j < dims[1]; ++j)
      for (int i = 0; i < dims[0]; ++i) {
        const double x = (i - 30) / 18.0, y = (j - 22) / 12.0, z = (k - 21) / 9.0;
        held[static_cast<size_t>(at(i, j, k))] = x * x + y * y + z * z <= 1;
      }
  const LatticeFreeNodes lattice = lattice_free_nodes(dims, held);
  const auto n = static_cast<Eigen::Index>(lattice.free_nodes.size());
  ASSERT_GT(n, 50000);
  auto field = [&](long long v) {
    const double i = static_cast<double>(v % dims[0]),
                 j = static_cast<double>((v / dims[0]) % dims[1]),
                 k = static_cast<double>(v / (1LL * dims[0] * dims[1]));
    return Eigen::Vector3d(0.3 * i - 0.1 * j + 2, 0.05 * k + 1, -0.2 * i + 0.4 * j - 0.3 * k);
  };
  Eigen::Matrix3Xd rhs = Eigen::Matrix3Xd::Zero(3, n);
  const long long step[3] = {1, dims[0], 1LL * dims[0] * dims[1]};
  for (Eigen::Index f = 0; f < n; ++f)
    for (int d = 0; d < 3; ++d)
      for (int side = 0; side < 2; ++side)
        if (lattice.neighbours[static_cast<size_t>(f)][static_cast<size_t>(2 * d + side)] < 0)
          rhs.col(f) +=
              field(lattice.free_nodes[static_cast<size_t>(f)] + (side ? step[d] : -step[d]));
  Eigen::Matrix3Xd x = Eigen::Matrix3Xd::Zero(3, n);
  const int iterations = solve_lattice_laplace(lattice, rhs, x);
  EXPECT_LE(iterations, 30);
  double worst = 0, scale = 0;
  for (Eigen::Index f = 0; f < n; ++f) {
    const Eigen::Vector3d u = field(lattice.free_nodes[static_cast<size_t>(f)]);
    worst = std::max(worst, (x.col(f) - u).cwiseAbs().maxCoeff());
    scale = std::max(scale, u.cwiseAbs().maxCoeff());
  }
  EXPECT_LT(worst, 1e-3 * scale);
}

// Nothing free: nothing to solve; every node free but the faces: zero.
TEST(LatticeLaplace, SolvesTheTrivialLattices) {
  const Eigen::Vector3i dims(9, 9, 9);
  const LatticeFreeNodes none = lattice_free_nodes(dims, std::vector<std::uint8_t>(729, 1));
  Eigen::Matrix3Xd x(3, 0);
  EXPECT_EQ(solve_lattice_laplace(none, Eigen::Matrix3Xd(3, 0), x), 0);
  const LatticeFreeNodes all = lattice_free_nodes(dims, std::vector<std::uint8_t>(729, 0));
  ASSERT_EQ(all.free_nodes.size(), 343u);
  Eigen::Matrix3Xd y = Eigen::Matrix3Xd::Ones(3, 343);
  solve_lattice_laplace(all, Eigen::Matrix3Xd::Zero(3, 343), y);
  EXPECT_LT(y.cwiseAbs().maxCoeff(), 1e-12);
}

}  // namespace
}  // namespace organfit::fitting::detail
