#include "organfit/fitting/global_fit.h"

#include <gtest/gtest.h>

#include <Eigen/LU>
#include <Eigen/SVD>
#include <random>

#include "organfit/fitting/skin.h"
#include "organfit/particles/lattice_fill.h"

namespace organfit::fitting {
namespace {

struct Body {
  particles::Positions x;
  double rho, a;
};

Body ellipsoid_body() {
  particles::CohesionParams p;
  p.r0_mm = 4.0;
  const double a = particles::fcc_equilibrium_spacing(particles::LennardJones(p));
  return {particles::fill_ellipsoid({50, 40, 34}, {0, 0, 0}, a), 2.0, a};
}

/// Points on the ellipsoid x^2/25^2 + y^2/20^2 + z^2/17^2 = 1 mapped by diag(s, 1/sqrt s, 1/sqrt
/// s).
std::vector<AttractivePoint> stretched_points(double s, int count, unsigned seed) {
  std::mt19937 rng(seed);
  std::normal_distribution<double> g;
  std::vector<AttractivePoint> pts;
  const Eigen::Vector3d semi(25, 20, 17), scale(s, 1 / std::sqrt(s), 1 / std::sqrt(s));
  for (int k = 0; k < count; ++k) {
    const Eigen::Vector3d d = Eigen::Vector3d(g(rng), g(rng), g(rng)).normalized();
    pts.push_back({scale.cwiseProduct(semi.cwiseProduct(d)), 1.0});
  }
  return pts;
}

TEST(GlobalFit, RecoversAVolumePreservingStretchFromSurfacePoints) {
  const Body b = ellipsoid_body();
  SkinDetector skin(b.rho, b.rho);
  skin.update(b.x);
  const SurfaceSamples samples = surface_samples(b.x, skin.skin(), b.rho);
  const AffineFit fit = fit_volume_preserving_affine(samples, stretched_points(1.2, 200, 1), {});
  const Eigen::Vector3d sv = Eigen::JacobiSVD<Eigen::Matrix3d>(fit.a).singularValues();
  EXPECT_NEAR(fit.a.determinant(), 1.0, 1e-9);
  EXPECT_NEAR(sv[0], 1.2, 0.03) << sv.transpose();
  EXPECT_NEAR(sv[1], 1 / std::sqrt(1.2), 0.03) << sv.transpose();
  EXPECT_NEAR(sv[2], 1 / std::sqrt(1.2), 0.03) << sv.transpose();
}

}  // namespace
}  // namespace organfit::fitting
