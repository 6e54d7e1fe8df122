#include "organfit/evaluation/synthetic.h"

#include <gtest/gtest.h>

#include <Eigen/LU>
#include <cmath>
#include <memory>
#include <random>
#include <string>
#include <vector>

namespace organfit::evaluation {
namespace {

using geometry::make_shape;
using geometry::Shape;
using geometry::shape_volume_mm3;

TEST(Deformation, IsVolumePreservingAndExactlyInvertible) {
  Deformation d;
  d.stretch = 1.2;
  d.bend_mm = 3.0;
  d.centre_mm = {1, 2, 3};
  d.half_length_mm = 25;
  const Eigen::Vector3d p(7, -4, 9);
  EXPECT_LT((d.inverse(d.apply(p)) - p).norm(), 1e-12);
  // Jacobian determinant by central differences.
  Eigen::Matrix3d j;
  for (int c = 0; c < 3; ++c) {
    Eigen::Vector3d h = Eigen::Vector3d::Zero();
    h[c] = 1e-6;
    j.col(c) = (d.apply(p + h) - d.apply(p - h)) / 2e-6;
  }
  EXPECT_NEAR(j.determinant(), 1.0, 1e-8);
  const Shape s = make_shape("egg", {50, 40, 34}, {0, 0, 0});
  const double v0 = shape_volume_mm3(s, 0.5);
  // The deformed body's volume, by counting voxel centres inside it.
  const auto in1 = deformed_inside(s, d);
  long long n = 0;
  for (double z = -30; z < 30; z += 0.5)
    for (double y = -30; y < 30; y += 0.5)
      for (double x = -40; x < 40; x += 0.5)
        n += in1({x, y, z});
  EXPECT_NEAR(n * 0.125, v0, 0.005 * v0);
}

TEST(Deformation, EveryFamilyIsVolumePreservingAndExactlyInvertible) {
  struct Family {
    const char* name;
    void (*set)(Deformation&);
  };
  const Family families[] = {{"twist", [](Deformation& d) { d.twist_rad = 0.4; }},
                             {"indent", [](Deformation& d) { d.indent_mm = -8; }},
                             {"push", [](Deformation& d) { d.push_mm = -6; }},
                             {"rigid",
                              [](Deformation& d) {
                                d.rotation_rad = Eigen::Vector3d(0.05, -0.02, 0.08);
                                d.shift_mm = Eigen::Vector3d(3, -1, 2);
                              }},
                             {"all", [](Deformation& d) {
                                d.stretch = 1.1, d.bend_mm = 2, d.twist_rad = 0.2, d.indent_mm = -5,
                                d.push_mm = 4, d.rotation_rad = Eigen::Vector3d(0, 0.1, 0),
                                d.shift_mm = Eigen::Vector3d(-2, 0, 1);
                              }}};
  for (const auto& f : families) {
    Deformation d;
    d.centre_mm = {1, -2, 3};
    d.half_length_mm = 25;
    f.set(d);
    for (const Eigen::Vector3d& p :
         {Eigen::Vector3d(7, -4, 9), Eigen::Vector3d(-12, 10, -3), Eigen::Vector3d(20, 1, 0)}) {
      EXPECT_LT((d.inverse(d.apply(p)) - p).norm(), 1e-10) << f.name;
      Eigen::Matrix3d j;
      for (int c = 0; c < 3; ++c) {
        Eigen::Vector3d h = Eigen::Vector3d::Zero();
        h[c] = 1e-6;
        j.col(c) = (d.apply(p + h) - d.apply(p - h)) / 2e-6;
      }
      EXPECT_NEAR(j.determinant(), 1.0, 1e-7) << f.name;
    }
  }
  // The indentation moves the posterior surface (+y) anteriorly at the centre by a.
  Deformation d;
  d.indent_mm = -8;
  EXPECT_NEAR(d.apply({0, 15, 0}).y(), 7.0, 1e-12);
}

/// A grid of 1 mm over [-20, 20]^3 carrying u(x) = (0.1 x, -0.05 y, -0.05 z) + (1, 2, -1)
/// plus a smooth bump: trilinear on the linear part exactly.
SampledDisplacement test_field(double bump_mm) {
  geometry::ImageGeometry g;
  g.size = {41, 41, 41};
  g.origin_mm = Eigen::Vector3d::Constant(-20);
  std::vector<float> u;
  for (int k = 0; k < 41; ++k)
    for (int j = 0; j < 41; ++j)
      for (int i = 0; i < 41; ++i) {
        const Eigen::Vector3d x = g.index_to_physical(Eigen::Vector3d(i, j, k));
        Eigen::Vector3d v =
            Eigen::Vector3d(0.1 * x.x(), -0.05 * x.y(), -0.05 * x.z()) + Eigen::Vector3d(1, 2, -1);
        v.y() += bump_mm * std::exp(-x.squaredNorm() / 50);
        for (int a = 0; a < 3; ++a)
          u.push_back(static_cast<float>(v[a]));
      }
  return make_sampled_displacement(g, u);
}

TEST(SampledDisplacement, InterpolatesALinearFieldExactlyAndIsInvertedByTheDeformation) {
  const SampledDisplacement f = test_field(0);
  const Eigen::Vector3d p(3.3, -7.25, 11.6);
  EXPECT_LT((f.at(p) - Eigen::Vector3d(1.33, 2.3625, -1.58)).norm(), 1e-5);
  EXPECT_NEAR(f.gradient(p)(0, 0), 0.1, 1e-5);
  EXPECT_NEAR(f.gradient(p)(1, 1), -0.05, 1e-5);
  EXPECT_NEAR(f.gradient(p)(0, 1), 0.0, 1e-5);
  // Beyond the grid: the border's value.
  EXPECT_LT((f.at({30, 0, 0}) - f.at({20, 0, 0})).norm(), 1e-6);

  Deformation d;
  d.field = std::make_shared<const SampledDisplacement>(test_field(4.0));
  EXPECT_FALSE(d.is_identity());
  EXPECT_GT(d.field->largest_mm, 4.0);
  for (const Eigen::Vector3d& q : {Eigen::Vector3d(0, 0, 0), Eigen::Vector3d(2, -3, 1),
                                   Eigen::Vector3d(-9, 4, 6), Eigen::Vector3d(12, 12, -12)}) {
    EXPECT_LT((d.apply(d.inverse(q)) - q).norm(), 1e-4) << q.transpose();
    EXPECT_LT((d.inverse(d.apply(q)) - q).norm(), 1e-4) << q.transpose();
  }
}

TEST(SampledDisplacement, RefusesAGridWithoutThreeValuesPerVoxelOrWithNaN) {
  geometry::ImageGeometry g;
  g.size = {2, 2, 2};
  EXPECT_THROW(make_sampled_displacement(g, std::vector<float>(23, 0.f)), std::invalid_argument);
  std::vector<float> u(24, 0.f);
  u[5] = std::nanf("");
  EXPECT_THROW(make_sampled_displacement(g, u), std::invalid_argument);
  g.direction = Eigen::Vector3d(1, -1, 1).asDiagonal();
  EXPECT_THROW(make_sampled_displacement(g, std::vector<float>(24, 0.f)), std::invalid_argument);
}

TEST(Sampling, PointsLieOnTheDeformedSurfaceWithinTheNoise) {
  const Shape s = make_shape("ellipsoid", {48, 38, 30}, {0, 0, 0});
  Deformation d;
  d.stretch = 1.2;
  d.half_length_mm = 24;
  SamplingOptions o;
  o.noise_mm = 0.0;
  o.count = 200;
  for (const auto& p : sample_deformed_surface(s, d, o)) {
    const Eigen::Vector3d q = d.inverse(p.p_mm).cwiseQuotient(Eigen::Vector3d(24, 19, 15));
    EXPECT_NEAR(q.norm(), 1.0, 0.002);
  }
  o.half_coverage = true;
  for (const auto& p : sample_deformed_surface(s, d, o))
    EXPECT_GE(p.p_mm.y(), -1e-9);
  const auto a = sample_deformed_surface(s, d, o), b = sample_deformed_surface(s, d, o);
  EXPECT_EQ(a[17].p_mm, b[17].p_mm);  // deterministic for a seed
}

// A hollow organ, as a bladder's wall: an ellipsoidal shell whose centroid lies in its
// cavity, outside it. Every point lies on its surface (outer or inner), none at the
// centroid; rays from the centroid ended at once, and most points were the centroid itself.
TEST(Sampling, PointsOfAMaskWhoseCentroidIsOutsideLieOnItsSurface) {
  const geometry::ImageGeometry g = geometry::grid_covering(
      {Eigen::Vector3d(-22, -18, -16), Eigen::Vector3d(22, 18, 16)}, 1.0, 0);
  const Shape outer = make_shape("ellipsoid", {40, 32, 28}, {0, 0, 0});
  const Shape inner = make_shape("ellipsoid", {24, 18, 14}, {0, 0, 0});
  auto mask = std::make_shared<geometry::LabelVolume>(g);
  for (int k = 0; k < g.size[2]; ++k)
    for (int j = 0; j < g.size[1]; ++j)
      for (int i = 0; i < g.size[0]; ++i) {
        const Eigen::Vector3d p = g.index_to_physical(Eigen::Vector3d(i, j, k));
        mask->at(i, j, k) = outer.inside(p) && !inner.inside(p);
      }
  const Shape s = geometry::make_mask_shape(mask);
  ASSERT_FALSE(s.inside(s.centre_mm));
  const Eigen::Vector3d origin = geometry::ray_origin_mm(s);
  SamplingOptions o;
  o.noise_mm = 0.0;
  o.count = 300;
  for (const bool half : {false, true}) {
    o.half_coverage = half;
    for (const auto& p : sample_deformed_surface(s, Deformation{}, o)) {
      const Eigen::Vector3d dir = (p.p_mm - origin).normalized();
      EXPECT_TRUE(s.inside(p.p_mm - 0.006 * dir));  // bisected to 0.01 mm
      EXPECT_FALSE(s.inside(p.p_mm + 0.006 * dir));
      EXPECT_GT((p.p_mm - s.centre_mm).norm(), 5.0);  // the cavity's nearest wall: 7 mm out
      if (half) {
        EXPECT_GE(dir.y(), -1e-9);
      }
    }
  }
}

// The truth of a case against a ball of known radius: the surfaces are concentric
// spheres 2 mm apart, the volumes and Dice analytic (to the 0.5 mm lattice's sampling).
TEST(KnownBody, MeasuresConcentricSpheresAnalytically) {
  const Eigen::Vector3d c(3.3, -7.1, 12.9);
  auto sphere = [c](const Eigen::Vector3d& p) { return (p - c).norm() <= 10.0; };
  KnownBody truth(sphere, {c.array() - 10.0, c.array() + 10.0}, 0.5);
  Eigen::Matrix3Xd one(3, 1);
  one.col(0) = c;
  const geometry::SurfaceComparison r = truth.compare(one, 8.0);
  const double pi = std::acos(-1.0);
  EXPECT_NEAR(r.volume_b_mm3, 4.0 / 3.0 * pi * 1000.0, 0.01 * 4.0 / 3.0 * pi * 1000.0);
  EXPECT_NEAR(r.volume_a_mm3, 4.0 / 3.0 * pi * 512.0, 0.01 * 4.0 / 3.0 * pi * 512.0);
  EXPECT_NEAR(r.dice, 2.0 * 512.0 / 1512.0, 0.01);
  EXPECT_NEAR(r.msd_mm, 2.0, 0.25);  // each surface voxel within half a voxel diagonal
  EXPECT_NEAR(r.hd95_mm, 2.0, 0.5);
}

// A body's measure depends neither on what was compared before (a far body samples
// nothing more) nor on bounds that miss part of the truth (the sampled part grows until
// the truth's faces are clear), and equals the comparison of the two masks on a lattice
// part that holds them.
TEST(KnownBody, AMeasureDoesNotDependOnWhatWasComparedBefore) {
  const Shape s = make_shape("egg", {30, 24, 20}, {1, 2, 3});
  Deformation d;
  d.stretch = 1.1, d.bend_mm = 2, d.centre_mm = {1, 2, 3}, d.half_length_mm = 15;
  const auto inside = deformed_inside(s, d);
  const geometry::Aabb bounds{Eigen::Vector3d(-25, -20, -15), Eigen::Vector3d(27, 24, 21)};
  Eigen::Matrix3Xd body(3, 3), far(3, 1);
  body << -8, 0, 8, 2, 2, 2, 3, 3, 3;
  far << 80, 2, 3;
  KnownBody fresh(inside, bounds, 0.5);
  const geometry::SurfaceComparison a = fresh.compare(body, 6.0);
  KnownBody grown(inside, bounds, 0.5);
  grown.compare(far, 6.0);
  EXPECT_EQ(grown.sampled_voxels(), fresh.sampled_voxels());
  const geometry::SurfaceComparison b = grown.compare(body, 6.0);
  EXPECT_NEAR(a.msd_mm, b.msd_mm, 1e-12);
  EXPECT_NEAR(a.hd95_mm, b.hd95_mm, 1e-12);
  EXPECT_EQ(a.dice, b.dice);
  EXPECT_EQ(a.volume_b_mm3, b.volume_b_mm3);
  // Bounds that cut the truth's +x end off: the truth is measured again where found.
  KnownBody loose(inside, {bounds.min_mm, Eigen::Vector3d(5, 24, 21)}, 0.5);
  EXPECT_GT(loose.sampled_voxels(), fresh.sampled_voxels() / 2);
  const geometry::SurfaceComparison c = loose.compare(body, 6.0);
  EXPECT_NEAR(a.msd_mm, c.msd_mm, 1e-12);
  EXPECT_EQ(a.dice, c.dice);
  EXPECT_EQ(a.volume_b_mm3, c.volume_b_mm3);
  // The same as both masks compared on the lattice part that holds them.
  const geometry::ImageGeometry g =
      fresh.lattice_covering({bounds.min_mm.cwiseMin(body.rowwise().minCoeff()),
                              bounds.max_mm.cwiseMax(body.rowwise().maxCoeff())},
                             2 * 6.0 + 2 * 0.5);
  geometry::LabelVolume t(g);
  for (int k = 0; k < g.size[2]; ++k)
    for (int j = 0; j < g.size[1]; ++j)
      for (int i = 0; i < g.size[0]; ++i)
        t.at(i, j, k) = inside(g.index_to_physical(Eigen::Vector3d(i, j, k)));
  const geometry::SurfaceComparison m =
      geometry::compare_masks(geometry::closed_body_on_grid(body, 6.0, 6.0, g), t);
  EXPECT_NEAR(a.msd_mm, m.msd_mm, 1e-9);
  EXPECT_NEAR(a.hd95_mm, m.hd95_mm, 1e-9);
  EXPECT_EQ(a.dice, m.dice);
  EXPECT_EQ(a.volume_a_mm3, m.volume_a_mm3);
  // Its centres miss round millimetres (a scanner grid's centres and midpoints).
  for (int axis = 0; axis < 3; ++axis) {
    const double f = g.origin_mm[axis] / 0.5 - std::floor(g.origin_mm[axis] / 0.5);
    EXPECT_GT(std::min(f, 1 - f), 0.1);
  }
  EXPECT_GT(a.dice, 0.3);
  EXPECT_LT(a.dice, 1.0);
  EXPECT_NEAR(a.volume_b_mm3, shape_volume_mm3(s, 0.5), 0.02 * shape_volume_mm3(s, 0.5));
}

// The deformations the benchmark composes, one family at a time and all together.
std::vector<Deformation> deformation_families() {
  Deformation base;
  base.centre_mm = {1, 2, 3}, base.half_length_mm = 30;
  std::vector<Deformation> out;
  Deformation d = base;
  d.stretch = 1.3, out.push_back(d);
  d = base, d.stretch = 0.8, out.push_back(d);
  d = base, d.bend_mm = 10, out.push_back(d);
  d = base, d.twist_rad = 0.6, out.push_back(d);
  d = base, d.indent_mm = -8, out.push_back(d);
  d = base, d.push_mm = 8, out.push_back(d);
  d = base, d.rotation_rad = {0.05, -0.03, 0.08}, d.shift_mm = {3, -2, 1}, out.push_back(d);
  d = base, d.stretch = 1.15, d.bend_mm = -6, d.twist_rad = -0.4, d.indent_mm = 5, d.push_mm = -5,
  d.rotation_rad = {0.02, 0.04, -0.03}, d.shift_mm = {-2, 2, 4};
  out.push_back(d);
  return out;
}

// inverse_radius bounds how far inverse() spreads a ball: every point sampled in a ball
// (its rim most of all) lands within the radius of the centre's image; and the bound is
// not loose by much (within 3x of the largest distance found).
TEST(Deformation, AnInverseRadiusHoldsTheBallsImage) {
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> uni(-1.0, 1.0);
  std::normal_distribution<double> gauss(0.0, 1.0);
  for (const Deformation& d : deformation_families()) {
    for (int b = 0; b < 300; ++b) {
      const Eigen::Vector3d c = d.centre_mm + 40 * Eigen::Vector3d(uni(rng), uni(rng), uni(rng));
      const double r = 0.1 + 8 * std::abs(uni(rng));
      const double bound = d.inverse_radius(c, r);
      const Eigen::Vector3d y = d.inverse(c);
      double largest = 0;
      for (int k = 0; k < 60; ++k) {
        Eigen::Vector3d dir(gauss(rng), gauss(rng), gauss(rng));
        dir.normalize();
        largest = std::max(largest, (d.inverse(c + r * dir) - y).norm());
      }
      ASSERT_LE(largest, bound) << "ball " << b;
      EXPECT_LT(bound, 3 * largest + 1e-6) << "ball " << b;
    }
  }
  Deformation with_field;
  with_field.field = std::make_shared<SampledDisplacement>();
  EXPECT_TRUE(std::isinf(with_field.inverse_radius({0, 0, 0}, 1)));  // iterative: no bound
}

// A truth with a ball test is the truth sampled voxel by voxel: each analytic shape under
// each family measures the same against the same bodies, to the last bit.
TEST(KnownBody, ABallTestGivesTheLabelsOfTestingEveryVoxel) {
  Eigen::Matrix3Xd body(3, 4);
  body << -10, 0, 10, 0, 2, 2, 2, 8, 3, 3, 3, 3;
  // A mask of thick slices too: the egg on a 1 x 1 x 2.5 mm grid.
  geometry::ImageGeometry g;
  g.size = {56, 42, 16}, g.spacing_mm = {1, 1, 2.5}, g.origin_mm = {-26.5, -18.5, -16};
  auto mask = std::make_shared<geometry::LabelVolume>(g);
  const Shape egg = make_shape("egg", {44, 30, 26}, {1, 2, 3});
  for (int k = 0; k < g.size[2]; ++k)
    for (int j = 0; j < g.size[1]; ++j)
      for (int i = 0; i < g.size[0]; ++i)
        mask->at(i, j, k) = egg.inside(g.index_to_physical(Eigen::Vector3d(i, j, k)));
  for (const char* kind : {"ellipsoid", "box", "egg", "lung", "mask"}) {
    const Shape s = std::string(kind) == "mask" ? geometry::make_mask_shape(mask)
                                                : make_shape(kind, {44, 30, 26}, {1, 2, 3});
    for (const Deformation& d : deformation_families()) {
      const InsideTest test = deformed_body(s, d);
      ASSERT_TRUE(test.ball);
      const geometry::Aabb bounds{Eigen::Vector3d(-40, -35, -30), Eigen::Vector3d(42, 39, 36)};
      const KnownBody each(test.inside, bounds, 1.0), blocks(test, bounds, 1.0);
      EXPECT_EQ(each.sampled_voxels(), blocks.sampled_voxels()) << kind;
      const geometry::SurfaceComparison a = each.compare(body, 7.0), b = blocks.compare(body, 7.0);
      EXPECT_EQ(a.volume_b_mm3, b.volume_b_mm3) << kind;
      EXPECT_EQ(a.dice, b.dice) << kind;
      EXPECT_EQ(a.msd_mm, b.msd_mm) << kind;
      EXPECT_EQ(a.hd95_mm, b.hd95_mm) << kind;
    }
  }
}
}  // namespace
}  // namespace organfit::evaluation
