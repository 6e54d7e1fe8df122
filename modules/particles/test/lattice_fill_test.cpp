// Filling bodies on the relaxed fcc lattice.
#include "organfit/particles/lattice_fill.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <tuple>

#include "organfit/particles/diagnostics.h"
#include "organfit/particles/integrator.h"
#include "organfit/particles/neighbour_list.h"
#include "test_systems.h"

namespace organfit::particles {
namespace {

TEST(FccEquilibriumSpacing, ZeroVirialAtTheComputedSpacing) {
  for (auto [m, n] : {std::pair{6, 12}, std::pair{4, 8}, std::pair{12, 24}}) {
    CohesionParams p;
    p.m = m, p.n = n, p.r0_mm = 2.0;
    const LennardJones law(p);
    const double a = fcc_equilibrium_spacing(law);
    EXPECT_LT(a, p.r0_mm);
    EXPECT_GT(a, 0.9 * p.r0_mm);
    // Virial sum_j r_j LJ(r_j) over the lattice is zero at equilibrium.
    State s(fill_box(Eigen::Vector3d::Constant(12 * p.r0_mm), Eigen::Vector3d::Zero(), a));
    const Eigen::Vector3d c = Eigen::Vector3d::Zero();
    double virial = 0;
    for (int j = 0; j < s.size(); ++j) {
      const double r = (s.x.col(j) - c).norm();
      if (r > 0) virial += r * law.force(r);
    }
    EXPECT_NEAR(virial, 0.0, 1e-9 * law.f_max() * p.r0_mm) << m << "," << n;
  }
  // 12-6 at r_c = 2.5 r0: the value quoted in METHOD.md s.8 is "about 0.976".
  EXPECT_NEAR(fcc_equilibrium_spacing(LennardJones(CohesionParams{})), 0.9758, 5e-4);
}

// Particles near in space are near in memory: first-shell neighbours lie a few dozen
// places apart in the fill's order, where a z, y, x order puts most of them a plane of
// the lattice apart (here over 500 places).
TEST(LatticeFill, FirstShellNeighboursAreNearInTheFillsOrder) {
  const double a = 2.0;
  const Positions x = fill_ellipsoid({80, 80, 80}, {0, 0, 0}, a);
  ASSERT_GT(x.cols(), 30000);
  NeighbourList list(1.05 * a, 0.01 * a);  // the first shell: a apart
  list.update(x);
  auto median_gap = [&](const std::vector<int>& place) {
    std::vector<long> gap;
    const auto& order = list.order();
    for (int s = 0; s < list.size(); ++s)
      for (int k = list.first()[s]; k < list.first()[s + 1]; ++k) {
        const int i = order[s], j = order[list.neighbours()[k]];
        if ((x.col(j) - x.col(i)).norm() < 1.05 * a) gap.push_back(std::labs(place[i] - place[j]));
      }
    std::nth_element(gap.begin(), gap.begin() + static_cast<long>(gap.size() / 2), gap.end());
    return gap[gap.size() / 2];
  };
  std::vector<int> fill(x.cols()), raster(x.cols());
  for (Eigen::Index i = 0; i < x.cols(); ++i)
    fill[i] = static_cast<int>(i), raster[i] = static_cast<int>(i);
  std::sort(raster.begin(), raster.end(), [&](int l, int r) {
    return std::make_tuple(x(2, l), x(1, l), x(0, l)) < std::make_tuple(x(2, r), x(1, r), x(0, r));
  });
  std::vector<int> raster_place(x.cols());
  for (Eigen::Index k = 0; k < x.cols(); ++k)
    raster_place[raster[k]] = static_cast<int>(k);
  const long ours = median_gap(fill), planes = median_gap(raster_place);
  EXPECT_LE(ours, 64) << "z, y, x order: " << planes;
  EXPECT_GT(planes, 500);
}

TEST(LatticeFill, CountsMatchTheLatticeDensity) {
  const double a = 1.0;
  const Positions box = fill_box({20, 20, 20}, {5, -3, 2}, a);
  const double expected = 8000.0 / fcc_volume_per_particle(a);
  EXPECT_NEAR(box.cols(), expected, 0.15 * expected);
  const Positions ell = fill_ellipsoid({20, 20, 20}, {0, 0, 0}, a);
  const double sphere = 4.0 / 3.0 * M_PI * 1000.0 / fcc_volume_per_particle(a);
  EXPECT_NEAR(ell.cols(), sphere, 0.05 * sphere);
  EXPECT_EQ(connected_components(ell, 1.1 * a), 1);
  EXPECT_NEAR(aspect_ratio(ell), 1.0, 0.02);
}

// Three balls apart and a stray particle: the two largest taken whole, in ascending index,
// the smallest ball and the stray left out; asking for more pieces than there are takes all.
TEST(Components, TheLargestOnesAreTakenWholeAndTheRestLeftOut) {
  const double a = 1.0;
  const Positions b1 = fill_ellipsoid({10, 10, 10}, {0, 0, 0}, a),
                  b2 = fill_ellipsoid({8, 8, 8}, {20, 0, 0}, a),
                  b3 = fill_ellipsoid({4, 4, 4}, {0, 20, 0}, a);
  Positions x(3, b3.cols() + b1.cols() + 1 + b2.cols());
  x << b3, b1, Eigen::Vector3d(0, 0, 40), b2;
  const std::vector<int> two = largest_components(x, 1.1 * a, 2);
  ASSERT_EQ(two.size(), static_cast<size_t>(b1.cols() + b2.cols()));
  EXPECT_TRUE(std::is_sorted(two.begin(), two.end()));
  EXPECT_EQ(two.front(), b3.cols());  // b1's first particle
  EXPECT_EQ(two.back(), x.cols() - 1);
  EXPECT_EQ(largest_component(x, 1.1 * a).size(), static_cast<size_t>(b1.cols()));
  EXPECT_EQ(largest_components(x, 1.1 * a, 9).size(), static_cast<size_t>(x.cols()));
  EXPECT_EQ(connected_components(x, 1.1 * a), 4);
}

TEST(LatticeFill, MaskWithRotatedDirectionMatchesTheAnalyticBody) {
  geometry::ImageGeometry g;
  g.size = {60, 50, 40};
  g.spacing_mm = {0.5, 0.5, 0.75};
  g.origin_mm = {-15, -12, -15};
  geometry::LabelVolume mask(g);
  const Eigen::Vector3d centre(0, 0.5, 0), semi(10, 6, 5);
  for (int k = 0; k < 40; ++k)
    for (int j = 0; j < 50; ++j)
      for (int i = 0; i < 60; ++i) {
        const Eigen::Vector3d p = g.index_to_physical(Eigen::Vector3d(i, j, k));
        if ((p - centre).cwiseQuotient(semi).squaredNorm() <= 1) mask.at(i, j, k) = 3;
      }
  const double a = 1.2;
  const Positions x = fill_mask(mask, 3, a);
  const double expected = mask.volume_mm3(3) / fcc_volume_per_particle(a);
  EXPECT_NEAR(x.cols(), expected, 0.06 * expected);
  for (int i = 0; i < x.cols(); ++i)
    EXPECT_EQ(mask.at_physical(x.col(i)), 3);
  EXPECT_EQ(fill_mask(mask, 7, a).cols(), 0);
}

TEST(LatticeFill, RelaxedFillHardlyMovesItsInterior) {
  CohesionParams p;
  p.r0_mm = 2.0;
  const LennardJones law(p);
  const double a = fcc_equilibrium_spacing(law);
  State s(fill_ellipsoid({30, 20, 20}, {0, 0, 0}, a));
  const Positions start = s.x;
  Model model = testing::cohesion_model(s.size(), p);
  IntegratorOptions opt;
  opt.damping = 2.0;
  opt.length_scale_mm = p.r0_mm;
  const RelaxResult r = relax(model, s, opt, 5000, 1e-8);
  EXPECT_TRUE(r.settled);
  // Particles deeper than 2 r0 from the centre plane barely move: the build spacing is right.
  double worst_inner = 0;
  for (int i = 0; i < s.size(); ++i) {
    const Eigen::Vector3d q = start.col(i).cwiseQuotient(Eigen::Vector3d(15, 10, 10));
    if (q.norm() < 0.4) worst_inner = std::max(worst_inner, (s.x.col(i) - start.col(i)).norm());
  }
  EXPECT_LT(worst_inner, 0.05 * p.r0_mm);
}

}  // namespace
}  // namespace organfit::particles
