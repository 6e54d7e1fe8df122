// The global stage's ridge system (src/global_solvers.h): (J^T W J + lambda I)^-1 g and the
// points' leverages (their sum the effective number of unknowns), factored in the points' space
// (fewer points than unknowns) or the unknowns' space (more), against the same system solved
// directly.
#include <gtest/gtest.h>

#include <Eigen/Dense>
#include <cmath>
#include <random>

#include "../src/global_solvers.h"

namespace organfit::fitting::detail {
namespace {

struct Case {
  Eigen::MatrixXd jac;
  Eigen::VectorXd w, g;
};

// J sparse as the fields' rows are (each point touches a few unknowns), some weights
// zero (outliers).
Case make_case(int m, int n, unsigned seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> value(-2, 2), unit(0, 1);
  Case c{Eigen::MatrixXd::Zero(m, n), Eigen::VectorXd(m), Eigen::VectorXd(n)};
  for (int k = 0; k < m; ++k) {
    for (int j = 0; j < n; ++j)
      if (unit(rng) < 0.2) c.jac(k, j) = value(rng);
    c.w(k) = unit(rng) < 0.1 ? 0.0 : unit(rng);
  }
  for (int j = 0; j < n; ++j)
    c.g(j) = value(rng);
  return c;
}

TEST(RidgeSystem, SolvesAsTheDirectSystemInEitherSpace) {
  const double lambda = 0.3;
  for (const auto& [m, n] : {std::pair{40, 120}, std::pair{300, 90}}) {  // both spaces
    const Case c = make_case(m, n, static_cast<unsigned>(m));
    const Eigen::MatrixXd s =
        c.jac.transpose() * c.w.asDiagonal() * c.jac + lambda * Eigen::MatrixXd::Identity(n, n);
    const Eigen::VectorXd expected = s.fullPivLu().solve(c.g);
    const RidgeSystem system(c.jac, c.w, lambda);
    EXPECT_LT((system.solve(c.g) - expected).norm(), 1e-10 * expected.norm()) << m << " x " << n;
    const double dof = (c.jac * s.inverse() * c.jac.transpose() * c.w.asDiagonal()).trace();
    EXPECT_NEAR(system.leverages().sum(), dof, 1e-9 * n) << m << " x " << n;
    EXPECT_GT(dof, 1.0);
  }
}

// The leverages are the hat matrix's diagonal, and r_k / (1 - h_k) is exactly the residual
// at point k of the ridge fit made without it (weight 0), in either space.
TEST(RidgeSystem, LeveragesGiveEachPointsResidualHadItBeenLeftOut) {
  const double lambda = 0.3;
  for (const auto& [m, n] : {std::pair{40, 120}, std::pair{300, 90}}) {
    const Case c = make_case(m, n, static_cast<unsigned>(m) + 7);
    Eigen::VectorXd y(m);  // the points' residuals at the parameters' zero
    for (int k = 0; k < m; ++k)
      y(k) = std::sin(0.7 * k) + 0.1 * k / m;
    auto fitted_residuals = [&](const Eigen::VectorXd& w) {  // r = y + J x, x minimising
      const RidgeSystem system(c.jac, w, lambda);            // |r|_W^2 + lambda |x|^2
      return Eigen::VectorXd(y - c.jac * system.solve(c.jac.transpose() * w.cwiseProduct(y)));
    };
    const RidgeSystem system(c.jac, c.w, lambda);
    const Eigen::VectorXd h = system.leverages();
    const Eigen::MatrixXd s =
        c.jac.transpose() * c.w.asDiagonal() * c.jac + lambda * Eigen::MatrixXd::Identity(n, n);
    const Eigen::VectorXd hat =
        (c.jac * s.inverse() * c.jac.transpose() * c.w.asDiagonal()).diagonal();
    EXPECT_LT((h - hat).cwiseAbs().maxCoeff(), 1e-10) << m << " x " << n;
    EXPECT_NEAR(h.sum(), hat.sum(), 1e-9 * n) << m << " x " << n;
    const Eigen::VectorXd r = fitted_residuals(c.w);
    int checked = 0;
    for (int k = 0; k < m; k += 7) {
      if (c.w(k) == 0) {
        EXPECT_EQ(h(k), 0.0) << k;  // an outlier takes none of its residual up
        continue;
      }
      Eigen::VectorXd without = c.w;
      without(k) = 0;
      const double left_out = fitted_residuals(without)(k);
      EXPECT_NEAR(r(k) / (1 - h(k)), left_out, 1e-9 * (1 + std::abs(left_out))) << m << " x " << n;
      EXPECT_GT(h(k), 0.0);
      ++checked;
    }
    EXPECT_GE(checked, 4);
  }
}

}  // namespace
}  // namespace organfit::fitting::detail
