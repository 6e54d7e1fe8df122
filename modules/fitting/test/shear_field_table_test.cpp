#include "organfit/fitting/shear_field_table.h"

#include <gtest/gtest.h>

#include <Eigen/LU>
#include <cmath>
#include <random>

#include "../src/central_differences.h"

using organfit::fitting::ShearFields;
using organfit::fitting::ShearFieldTable;
using organfit::fitting::detail::central_gradient;
using organfit::fitting::detail::central_jacobian;

namespace {

/// Random heights on a grid of sigma 7 mm over a 60 x 90 x 120 mm box.
ShearFields random_fields(unsigned seed) {
  ShearFields f = ShearFields::over(Eigen::Vector3d(-30, -45, -60), Eigen::Vector3d(30, 45, 60), 7);
  std::mt19937 rng(seed);
  std::normal_distribution<double> height(0, 0.8);
  for (Eigen::Index i = 0; i < f.weights.size(); ++i)
    f.weights[i] = height(rng);
  return f;
}

/// grad f_a at q from every bump (none left out), the coordinate a's entry 0.
Eigen::Vector3d bump_gradient(const ShearFields& f, int a, const Eigen::Vector3d& q) {
  const int b = a == 0 ? 1 : 0, c = a == 2 ? 1 : 2;
  Eigen::Vector3d g = Eigen::Vector3d::Zero();
  for (int j = 0; j < f.count(c); ++j)
    for (int i = 0; i < f.count(b); ++i) {
      const double tb = (q(b) - f.origin_mm(b)) / f.sigma_mm - i,
                   tc = (q(c) - f.origin_mm(c)) / f.sigma_mm - j;
      const double e = f.weights(a * f.block() + i + f.count(b) * j) *
                       std::exp(-0.5 * (tb * tb + tc * tc)) / f.sigma_mm;
      g(b) -= tb * e, g(c) -= tc * e;
    }
  return g;
}

}  // namespace

TEST(ShearFieldTable, FieldsAndGradientsWithinTheStatedErrorOfTheBumps) {
  const ShearFields f = random_fields(3);
  const ShearFieldTable table(f);
  std::mt19937 rng(4);
  std::uniform_real_distribution<double> u(-1, 1);
  for (int a = 0; a < 3; ++a) {
    const double w = f.largest_weight(a), value = table.error().value_mm[static_cast<size_t>(a)],
                 gradient = table.error().gradient[static_cast<size_t>(a)];
    // Small: of order 1e-5 of the largest height, 2e-3 of it per sigma for the gradient.
    EXPECT_LT(value, 2e-5 * w);
    EXPECT_LT(gradient, 2e-3 * w / f.sigma_mm);
    double worst_value = 0, worst_gradient = 0;
    for (int k = 0; k < 2000; ++k) {
      const Eigen::Vector3d q(50 * u(rng), 70 * u(rng), 90 * u(rng));  // beyond the box too
      // The bumps leave out those below 1e-6 (at most 1e-4 of the largest height in all).
      worst_value = std::max(worst_value, std::abs(table.field(a, q) - f.field(a, q)) - 1e-4 * w);
      const Eigen::Vector3d fd =
          central_gradient([&](const Eigen::Vector3d& x) { return table.field(a, x); }, q, 1e-4);
      worst_gradient = std::max(worst_gradient, (fd - bump_gradient(f, a, q)).norm());
    }
    EXPECT_LE(worst_value, value) << "field " << a;
    EXPECT_LE(worst_gradient, gradient + 1e-6) << "field " << a;  // 1e-6: the differences'
    EXPECT_GT(worst_gradient, 0.0);
  }
}

TEST(ShearFieldTable, ApplyAndInverseAreExactInversesAndKeepVolume) {
  const ShearFields f = random_fields(5);
  const ShearFieldTable table(f);
  std::mt19937 rng(6);
  std::uniform_real_distribution<double> u(-1, 1);
  for (int k = 0; k < 200; ++k) {
    const Eigen::Vector3d p(40 * u(rng), 60 * u(rng), 80 * u(rng));
    EXPECT_LT((table.inverse(table.apply(p)) - p).norm(), 1e-12);
    EXPECT_LT((table.apply(table.inverse(p)) - p).norm(), 1e-12);
    EXPECT_GT((table.apply(p) - p).norm(), 0.0);
    const Eigen::Matrix3d j =
        central_jacobian([&](const Eigen::Vector3d& x) { return table.apply(x); }, p, 1e-5);
    EXPECT_NEAR(j.determinant(), 1.0, 1e-7);
  }
}

TEST(ShearFieldTable, NoFieldsAndFarPointsAreLeftWhereTheyAre) {
  const ShearFieldTable none{ShearFields{}};
  EXPECT_TRUE(none.empty());
  const Eigen::Vector3d p(1, 2, 3);
  EXPECT_EQ(none.apply(p), p);
  EXPECT_EQ(none.inverse(p), p);
  const ShearFieldTable table(random_fields(7));
  EXPECT_FALSE(table.empty());
  // 6 sigmas beyond the outermost centres (box + 1 sigma): zero; not finite: zero.
  EXPECT_EQ(table.field(0, Eigen::Vector3d(0, 0, 60 + 8 * 7)), 0.0);
  EXPECT_EQ(table.field(2, Eigen::Vector3d(NAN, 0, 0)), 0.0);
}

TEST(ShearFieldTable, FewerNodesWhereTheBumpsAreManyWithinTheErrorItStates) {
  // sigma 1 mm over a 200 x 300 x 400 mm box: 10 nodes a sigma would pass 8M nodes.
  ShearFields f =
      ShearFields::over(Eigen::Vector3d(-100, -150, -200), Eigen::Vector3d(100, 150, 200), 1);
  std::mt19937 rng(8);
  std::normal_distribution<double> height(0, 0.2);
  for (Eigen::Index i = 0; i < f.weights.size(); ++i)
    f.weights[i] = height(rng);
  const ShearFieldTable table(f);
  EXPECT_LT(table.nodes_per_sigma(), ShearFieldTable::kNodesPerSigma);
  EXPECT_GE(table.nodes_per_sigma(), 4);
  std::uniform_real_distribution<double> u(-1, 1);
  for (int a = 0; a < 3; ++a) {
    const double w = f.largest_weight(a);
    for (int k = 0; k < 60; ++k) {
      const Eigen::Vector3d q(90 * u(rng), 140 * u(rng), 190 * u(rng));
      EXPECT_LE(std::abs(table.field(a, q) - f.field(a, q)),
                table.error().value_mm[static_cast<size_t>(a)] + 1e-4 * w);
      const Eigen::Vector3d fd =
          central_gradient([&](const Eigen::Vector3d& x) { return table.field(a, x); }, q, 1e-5);
      EXPECT_LE((fd - bump_gradient(f, a, q)).norm(),
                table.error().gradient[static_cast<size_t>(a)] + 1e-5);
    }
  }
}
