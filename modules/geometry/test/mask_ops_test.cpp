#include "organfit/geometry/mask_ops.h"

#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <limits>
#include <random>

namespace organfit::geometry {
namespace {

/// A voxel's index (i, j, k) on `g` from its linear index.
Eigen::Vector3d index_of(const ImageGeometry& g, long long v) {
  return Eigen::Vector3d(static_cast<double>(v % g.size[0]),
                         static_cast<double>((v / g.size[0]) % g.size[1]),
                         static_cast<double>(v / (1LL * g.size[0] * g.size[1])));
}

/// The brute-force squared distance (mm^2) from voxel `v` to the nearest voxel `w` with
/// target(w), infinity when there is none: every voxel of the grid tried.
template <class Target>
double brute_force_squared_distance(const ImageGeometry& g, long long v, Target&& target) {
  double best = std::numeric_limits<double>::infinity();
  for (long long w = 0; w < g.voxel_count(); ++w)
    if (target(w))
      best =
          std::min(best, g.spacing_mm.cwiseProduct(index_of(g, w) - index_of(g, v)).squaredNorm());
  return best;
}

TEST(DistanceTransform, MatchesBruteForceOnAnisotropicGrid) {
  ImageGeometry g;
  g.size = {13, 9, 7};
  g.spacing_mm = {0.5, 0.8, 1.3};
  std::vector<std::uint8_t> f(g.voxel_count(), 0);
  std::mt19937 rng(3);
  for (auto& v : f)
    v = (rng() % 37) == 0;
  const auto d = squared_distance_transform(f, g);
  for (long long v = 0; v < g.voxel_count(); ++v)
    EXPECT_NEAR(
        d[static_cast<size_t>(v)],
        brute_force_squared_distance(g, v, [&](long long w) { return f[static_cast<size_t>(w)]; }),
        1e-9);
}

TEST(FeatureTransform, NamesANearestFeatureVoxelAtTheTransformsDistance) {
  // Random features from sparse to dense on anisotropic grids, and none: the voxel named is
  // a feature voxel at the brute-force least distance (within rounding), and the distance
  // transform's value; -1 everywhere when there is no feature.
  std::mt19937 rng(11);
  for (int trial = 0; trial < 6; ++trial) {
    ImageGeometry g;
    g.size = {12 + trial, 9 + trial % 3, 7 + 2 * (trial % 2)};
    g.spacing_mm = {0.5 + 0.1 * trial, 0.8, 1.3};
    std::vector<std::uint8_t> f(g.voxel_count());
    for (auto& v : f)
      v = trial == 5 ? 0 : (rng() % (2 + 15 * trial)) == 0;
    const std::vector<int> nearest = nearest_feature_transform(f, g);
    const auto d = squared_distance_transform(f, g);
    ASSERT_EQ(nearest.size(), f.size());
    for (long long v = 0; v < g.voxel_count(); ++v) {
      const double best = brute_force_squared_distance(
          g, v, [&](long long w) { return f[static_cast<size_t>(w)] != 0; });
      const int got = nearest[static_cast<size_t>(v)];
      if (std::isinf(best)) {
        ASSERT_EQ(got, -1) << "trial " << trial;
        continue;
      }
      ASSERT_GE(got, 0);
      ASSERT_TRUE(f[static_cast<size_t>(got)]) << "trial " << trial << " voxel " << v;
      EXPECT_NEAR(g.spacing_mm.cwiseProduct(index_of(g, got) - index_of(g, v)).squaredNorm(), best,
                  1e-9)
          << "trial " << trial << " voxel " << v;
      EXPECT_NEAR(d[static_cast<size_t>(v)], best, 1e-9);
    }
  }
}

TEST(DistanceTransform, AcrossIsBothTransformsEachWhereItIsAsked) {
  // Random masks from sparse to dense on anisotropic grids, lines wholly inside, wholly
  // outside and mixed, and the empty and full masks: to the inside at outside voxels, to
  // the outside at inside voxels, value for value with the two transforms, and within
  // rounding of the brute-force nearest voxel of the other side.
  std::mt19937 rng(5);
  for (int trial = 0; trial < 10; ++trial) {
    ImageGeometry g;
    g.size = {11 + trial, 9 + trial % 3, 7 + 2 * (trial % 2)};
    g.spacing_mm = {0.5 + 0.1 * trial, 0.8, 1.3};
    std::vector<std::uint8_t> inside(g.voxel_count());
    const unsigned one_in = 1 + trial;  // trial 0: full
    for (auto& v : inside)
      v = trial == 9 ? 0 : (rng() % one_in) == 0;  // trial 9: empty
    if (trial == 4)  // a solid block: whole lines inside along every axis
      for (int k = 1; k < 6; ++k)
        for (int j = 2; j < 8; ++j)
          for (int i = 0; i < g.size[0]; ++i)
            inside[g.linear_index(i, j, k)] = 1;
    std::vector<std::uint8_t> outside(inside.size());
    for (size_t v = 0; v < inside.size(); ++v)
      outside[v] = !inside[v];
    const auto across = squared_distance_across(inside, g);
    const auto to_inside = squared_distance_transform(inside, g);
    const auto to_outside = squared_distance_transform(outside, g);
    for (size_t v = 0; v < inside.size(); ++v)
      ASSERT_EQ(across[v], inside[v] ? to_outside[v] : to_inside[v]) << "trial " << trial;
    for (long long v = 0; v < g.voxel_count(); ++v) {
      const bool here = inside[static_cast<size_t>(v)];
      const double best = brute_force_squared_distance(g, v, [&](long long w) {
        return static_cast<bool>(inside[static_cast<size_t>(w)]) != here;
      });
      const double got = across[static_cast<size_t>(v)];
      if (std::isinf(best))
        ASSERT_TRUE(std::isinf(got)) << "trial " << trial;
      else
        ASSERT_NEAR(got, best, 1e-9) << "trial " << trial;
    }
  }
}

TEST(MaskOps, SurfaceVoxelsAreTheInsideVoxelsWithAFaceNeighbourOutsideOrOnTheEdge) {
  // Rows of several lengths (shorter than eight voxels, not a multiple of eight), solid
  // blocks with holes, and labels other than 1: the scan by eight voxels at a time must
  // find what the definition does, voxel by voxel.
  std::mt19937 rng(11);
  for (const Eigen::Vector3i& size : {Eigen::Vector3i(5, 4, 3), Eigen::Vector3i(37, 11, 9),
                                      Eigen::Vector3i(64, 6, 5), Eigen::Vector3i(1, 7, 4)}) {
    LabelVolume mask;
    mask.geometry.size = {size.x(), size.y(), size.z()};
    mask.labels.assign(mask.geometry.voxel_count(), 0);
    for (int k = 0; k < size.z(); ++k)
      for (int j = 0; j < size.y(); ++j)
        for (int i = 0; i < size.x(); ++i)
          if (i > size.x() / 5 && rng() % 23 != 0)
            mask.at(i, j, k) = static_cast<std::uint8_t>(1 + rng() % 255 * (rng() % 2));
    std::vector<Eigen::Vector3i> expected;
    for (int k = 0; k < size.z(); ++k)
      for (int j = 0; j < size.y(); ++j)
        for (int i = 0; i < size.x(); ++i) {
          if (!mask.at(i, j, k)) continue;
          bool surface = false;
          for (int d = 0; d < 3; ++d)
            for (const int step : {-1, 1}) {
              Eigen::Vector3i n(i, j, k);
              n(d) += step;
              surface = surface || n(d) < 0 || n(d) >= size(d) || !mask.at(n.x(), n.y(), n.z());
            }
          if (surface) expected.emplace_back(i, j, k);
        }
    EXPECT_EQ(surface_voxels(mask), expected) << size.transpose();
    const std::vector<std::uint8_t> flags = surface_of(mask);
    EXPECT_EQ(static_cast<size_t>(std::count(flags.begin(), flags.end(), 1)), expected.size());
    for (const Eigen::Vector3i& v : expected)
      EXPECT_EQ(flags[static_cast<size_t>(mask.geometry.linear_index(v.x(), v.y(), v.z()))], 1);
  }
}

TEST(MaskOps, BallVolumeAndSurfaceDistanceOfConcentricSpheres) {
  const ImageGeometry g =
      grid_covering({Eigen::Vector3d::Constant(-12), Eigen::Vector3d::Constant(12)}, 0.25, 1);
  Eigen::Matrix3Xd c = Eigen::Matrix3Xd::Zero(3, 1);
  const LabelVolume a = rasterize_balls(c, 10.0, g), b = rasterize_balls(c, 8.0, g);
  EXPECT_NEAR(a.volume_mm3(1), 4.0 / 3 * M_PI * 1000, 0.01 * 4.0 / 3 * M_PI * 1000);
  const SurfaceComparison r = compare_masks(a, b);
  EXPECT_NEAR(r.msd_mm, 2.0, 0.15);
  EXPECT_NEAR(r.hd95_mm, 2.0, 0.3);
  EXPECT_NEAR(r.dice, 2 * 512.0 / (1000 + 512), 0.01);
  const SurfaceComparison same = compare_masks(a, a);
  EXPECT_EQ(same.msd_mm, 0.0);
  EXPECT_EQ(same.dice, 1.0);
}

// compare_masks finds surface distances among the surface voxels alone; they must be
// the distance transform's values at those voxels, on an anisotropic grid, for random
// shapes with several components, and infinite when one surface is empty. On the larger
// grid many lie beyond the 4 voxels its search's grid answers (the k-d tree's).
TEST(MaskOps, SurfaceDistancesAreTheDistanceTransformsValues) {
  for (const Eigen::Vector3i& size : {Eigen::Vector3i(21, 17, 11), Eigen::Vector3i(60, 45, 20)}) {
    ImageGeometry g;
    g.size = {size.x(), size.y(), size.z()};
    g.spacing_mm = {0.5, 0.8, 1.3};
    std::mt19937 rng(7);
    for (int trial = 0; trial < 4; ++trial) {
      LabelVolume a(g), b(g);
      for (int blob = 0; blob < 3; ++blob) {
        const Eigen::Vector3d ca(rng() % size.x(), rng() % size.y(), rng() % size.z()),
            cb(rng() % size.x(), rng() % size.y(), rng() % size.z());
        const double ra = 1.5 + rng() % 4, rb = 1.5 + rng() % 4;
        for (int k = 0; k < g.size[2]; ++k)
          for (int j = 0; j < g.size[1]; ++j)
            for (int i = 0; i < g.size[0]; ++i) {
              const Eigen::Vector3d p(i, j, k);
              if ((p - ca).norm() <= ra) a.at(i, j, k) = 1;
              if ((p - cb).norm() <= rb) b.at(i, j, k) = 1;
            }
      }
      const auto sa = surface_of(a), sb = surface_of(b);
      const auto da = squared_distance_transform(sa, g), db = squared_distance_transform(sb, g);
      std::vector<double> dist;
      for (size_t i = 0; i < sa.size(); ++i) {
        if (sa[i]) dist.push_back(std::sqrt(db[i]));
        if (sb[i]) dist.push_back(std::sqrt(da[i]));
      }
      double sum = 0;
      for (double d : dist)
        sum += d;
      const size_t k = static_cast<size_t>(std::ceil(0.95 * dist.size())) - 1;
      std::nth_element(dist.begin(), dist.begin() + static_cast<long>(k), dist.end());
      const SurfaceComparison r = compare_masks(a, b);
      EXPECT_NEAR(r.msd_mm, sum / static_cast<double>(dist.size()), 1e-12) << trial;
      EXPECT_NEAR(r.hd95_mm, dist[k], 1e-12) << trial;
      if (size.x() == 60) {
        EXPECT_GT(dist[k], 4 * 1.3) << trial;  // the tree's part tested
      }
    }
  }
  ImageGeometry g;
  g.size = {21, 17, 11};
  g.spacing_mm = {0.5, 0.8, 1.3};
  LabelVolume empty(g), one(g);
  one.at(3, 4, 5) = 1;
  EXPECT_TRUE(std::isinf(compare_masks(one, empty).msd_mm));
}

// Distances from any points (on the mask's lattice, on a part of it offset by whole
// voxels, off it, near and far) are the least distance to a surface voxel's centre.
TEST(MaskOps, MaskSurfaceDistancesAreTheNearestSurfaceVoxelsFromAnyPoint) {
  ImageGeometry g;
  g.size = {40, 30, 16};
  g.spacing_mm = {0.6, 0.9, 1.7};
  g.origin_mm = {-3.3, 2.1, 7.7};
  LabelVolume mask(g);
  for (int k = 0; k < g.size[2]; ++k)
    for (int j = 0; j < g.size[1]; ++j)
      for (int i = 0; i < g.size[0]; ++i)
        mask.at(i, j, k) =
            Eigen::Vector3d((i - 20) / 9.0, (j - 14) / 7.0, (k - 8) / 4.0).norm() <= 1;
  const MaskSurface surface(mask);
  const Eigen::Matrix3Xd& centres = surface.points_mm();
  ASSERT_GT(centres.cols(), 200);
  std::mt19937 rng(5);
  std::uniform_int_distribution<int> voxel(-6, 46);
  std::uniform_real_distribution<double> frac(0.0, 1.0);
  Eigen::Matrix3Xd q(3, 1500);
  for (int c = 0; c < q.cols(); ++c) {
    Eigen::Vector3d idx(voxel(rng), voxel(rng) * 0.7, voxel(rng) * 0.4);
    idx = idx.array().round();
    if (c % 3 == 2) idx += Eigen::Vector3d(frac(rng), frac(rng), frac(rng));  // off the lattice
    q.col(c) = g.index_to_physical(idx);
  }
  const std::vector<double> d = surface.distances_from(q);
  int near = 0, far = 0;
  for (int c = 0; c < q.cols(); ++c) {
    const double truth = (centres.colwise() - q.col(c)).colwise().norm().minCoeff();
    EXPECT_NEAR(d[static_cast<size_t>(c)], truth, 1e-9) << c;
    if (c % 3 != 2) (truth <= 4 * 0.6 ? near : far)++;  // on the lattice: within its reach?
  }
  EXPECT_GT(near, 50);
  EXPECT_GT(far, 100);
}

// The test a row's chord narrows to gives the voxels of testing every voxel of the box.
TEST(MaskOps, BallsOnAnAlignedGridAreTheVoxelsWithinTheirRadius) {
  ImageGeometry g;
  g.size = {37, 29, 13};
  g.spacing_mm = {0.5, 0.7, 2.5};
  g.origin_mm = {1.1, -2.3, 0.45};
  std::mt19937 rng(9);
  std::uniform_real_distribution<double> uni(0.0, 1.0);
  Eigen::Matrix3Xd c(3, 40);
  for (int b = 0; b < c.cols(); ++b)
    c.col(b) = g.index_to_physical(
        Eigen::Vector3d(40 * uni(rng) - 2, 31 * uni(rng) - 1, 15 * uni(rng) - 1));
  c.col(0) = g.index_to_physical(Eigen::Vector3d(10, 10, 5));  // radius 2.5: rims on centres
  const double r = 2.5;
  const LabelVolume m = rasterize_balls(c, r, g);
  long long set = 0;
  for (int k = 0; k < g.size[2]; ++k)
    for (int j = 0; j < g.size[1]; ++j)
      for (int i = 0; i < g.size[0]; ++i) {
        const Eigen::Vector3d p = g.index_to_physical(Eigen::Vector3d(i, j, k));
        bool in = false;
        for (int b = 0; b < c.cols(); ++b)
          in = in || (p - c.col(b)).squaredNorm() <= r * r;
        ASSERT_EQ(m.at(i, j, k), in ? 1 : 0) << i << " " << j << " " << k;
        set += in;
      }
  EXPECT_GT(set, 500);
}

TEST(MaskOps, BallsOnARotatedGridLandWhereThePhysicalBallIs) {
  ImageGeometry g;
  g.size = {30, 30, 30};
  g.origin_mm = {5, -7, 3};
  g.direction = Eigen::AngleAxisd(0.6, Eigen::Vector3d(1, 1, 0).normalized()).toRotationMatrix();
  const Eigen::Vector3d centre = g.index_to_physical(Eigen::Vector3d(15, 12, 18));
  const LabelVolume m = rasterize_balls(centre, 5.0, g);
  EXPECT_EQ(m.at(15, 12, 18), 1);
  EXPECT_NEAR(m.volume_mm3(1), 4.0 / 3 * M_PI * 125, 0.06 * 4.0 / 3 * M_PI * 125);
  for (int k = 0; k < 30; ++k)
    for (int j = 0; j < 30; ++j)
      for (int i = 0; i < 30; ++i)
        if (m.at(i, j, k)) {
          EXPECT_LE((g.index_to_physical(Eigen::Vector3d(i, j, k)) - centre).norm(), 5.0 + 1e-9);
        }
}

TEST(MaskOps, ClosedBodyOnALargeGridEqualsClosingTheWholeGrid) {
  ImageGeometry g;
  g.size = {80, 70, 30};
  g.spacing_mm = {0.7, 0.7, 2.0};
  g.origin_mm = {-30, -20, -10};
  Eigen::Matrix3Xd c(3, 27);
  int n = 0;
  for (int k = 0; k < 3; ++k)
    for (int j = 0; j < 3; ++j)
      for (int i = 0; i < 3; ++i)
        c.col(n++) = Eigen::Vector3d(2.0 * i, 2.0 * j, 2.0 * k + 20);
  LabelVolume whole = rasterize_balls(c, 1.0, g);
  close_mask(whole, 1.0);
  const LabelVolume cropped = closed_body_on_grid(c, 1.0, 1.0, g);
  EXPECT_GT(whole.count(1), 0);
  EXPECT_EQ(cropped.labels, whole.labels);
  // The part alone: voxels of the grid (same spacing, origin on a voxel), the same labels.
  const LabelVolume part = closed_body(c, 1.0, 1.0, g);
  EXPECT_LT(part.geometry.voxel_count(), g.voxel_count() / 20);
  const Eigen::Vector3d o = g.physical_to_index(part.geometry.origin_mm);
  EXPECT_LT((o - o.array().round().matrix()).norm(), 1e-9);
  EXPECT_EQ(part.count(1), whole.count(1));
  for (int k = 0; k < part.geometry.size[2]; ++k)
    for (int j = 0; j < part.geometry.size[1]; ++j)
      for (int i = 0; i < part.geometry.size[0]; ++i)
        ASSERT_EQ(part.at(i, j, k), whole.at(i + static_cast<int>(std::lround(o.x())),
                                             j + static_cast<int>(std::lround(o.y())),
                                             k + static_cast<int>(std::lround(o.z()))));
  EXPECT_EQ(closed_body(Eigen::Matrix3Xd::Constant(3, 1, 1e4), 1.0, 1.0, g).geometry.voxel_count(),
            0);
  EXPECT_EQ(closed_body_on_grid(Eigen::Matrix3Xd::Constant(3, 1, 1e4), 1.0, 1.0, g).count(1),
            0);  // off the grid
}

// The closing by the definition: the voxels farther than r from every voxel farther than
// r from the mask, both by the distance transform of the whole grid.
std::vector<std::uint8_t> closing_by_distance_transforms(const LabelVolume& mask, double r) {
  const double r2 = r * r;
  const auto to_body = squared_distance_transform(mask.labels, mask.geometry);
  std::vector<std::uint8_t> outside(to_body.size());
  for (size_t i = 0; i < outside.size(); ++i)
    outside[i] = to_body[i] > r2;
  const auto to_outside = squared_distance_transform(outside, mask.geometry);
  std::vector<std::uint8_t> closed(outside.size());
  for (size_t i = 0; i < closed.size(); ++i)
    closed[i] = to_outside[i] > r2;
  return closed;
}

TEST(MaskOps, ClosingEqualsItsDefinitionByDistanceTransforms) {
  // Random balls and noise voxels on anisotropic grids, radii on and off the spacing's
  // multiples (rims exactly on a voxel centre included), bodies touching the grid's edge.
  std::mt19937 rng(11);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  long long changed = 0;
  for (int trial = 0; trial < 12; ++trial) {
    ImageGeometry g;
    g.size = {20 + trial, 17, 11 + trial % 4};
    g.spacing_mm = trial % 3 == 0 ? Eigen::Vector3d(0.5, 0.5, 0.5)
                                  : Eigen::Vector3d(0.4 + 0.1 * (trial % 4), 0.7, 1.3);
    Eigen::Matrix3Xd c(3, 6 + trial);
    const Eigen::Vector3d extent =
        g.spacing_mm.cwiseProduct(Eigen::Vector3d(g.size[0], g.size[1], g.size[2]));
    for (Eigen::Index k = 0; k < c.cols(); ++k)
      c.col(k) = Eigen::Vector3d(u(rng), u(rng), u(rng)).cwiseProduct(extent);
    LabelVolume mask = rasterize_balls(c, 0.6 + 0.2 * (trial % 5), g);
    for (auto& v : mask.labels)
      if (rng() % 53 == 0) v = 1;
    const double r = trial % 3 == 0 ? 1.0 : 0.65 + 0.37 * (trial % 4);
    const std::vector<std::uint8_t> expected = closing_by_distance_transforms(mask, r);
    const std::vector<std::uint8_t> before = mask.labels;
    close_mask(mask, r);
    ASSERT_EQ(mask.labels, expected) << "trial " << trial;
    for (size_t i = 0; i < before.size(); ++i)
      changed += before[i] != mask.labels[i];
  }
  EXPECT_GT(changed, 100);  // the closings did fill gaps
  // Rows longer than 64 voxels, and a ball reaching more than 64 voxels along x; labels
  // other than 1 (any nonzero is the body's, as the transform takes it).
  for (int trial = 0; trial < 3; ++trial) {
    ImageGeometry g;
    g.size = {trial == 2 ? 150 : 70 + 40 * trial, 9, 8};
    g.spacing_mm = trial == 2 ? Eigen::Vector3d(0.015, 0.4, 0.5) : Eigen::Vector3d(0.3, 0.5, 0.6);
    LabelVolume mask(g);
    for (auto& v : mask.labels)
      v = rng() % 9 == 0 ? static_cast<std::uint8_t>(1 + rng() % 255) : 0;
    const double r = trial == 2 ? 1.0 : 0.9 + 0.3 * trial;
    const std::vector<std::uint8_t> expected = closing_by_distance_transforms(mask, r);
    close_mask(mask, r);
    ASSERT_EQ(mask.labels, expected) << "wide trial " << trial;
  }
  LabelVolume empty(ImageGeometry{});
  close_mask(empty, 1.0);
  LabelVolume full;
  full.geometry.size = {5, 4, 3};
  full.labels.assign(60, 1);
  close_mask(full, 1.0);
  EXPECT_EQ(full.count(1), 60);
}

TEST(MaskOps, ClosingFillsTheGapsOfAPackingButNotItsOutline) {
  // A simple cubic packing of touching balls of radius 1 (spacing 2) over a 20 mm cube:
  // the union of balls is ~52% of the cube; closed, it is the cube to within a shell.
  Eigen::Matrix3Xd c(3, 1000);
  int n = 0;
  for (int k = 0; k < 10; ++k)
    for (int j = 0; j < 10; ++j)
      for (int i = 0; i < 10; ++i)
        c.col(n++) = Eigen::Vector3d(2 * i + 1, 2 * j + 1, 2 * k + 1);
  const double open = particle_body_volume_mm3(c, 1.0, 0.2, 0.0);
  const double closed = particle_body_volume_mm3(c, 1.0, 0.2, 1.5);
  // Discretisation: a ball of radius 5 voxels holds 515 voxel centres (523.6 in the
  // continuum) and touching balls share their contact voxels: -4% here.
  EXPECT_NEAR(open, 1000 * 4.0 / 3 * M_PI, 0.05 * 1000 * 4.0 / 3 * M_PI);
  EXPECT_GT(closed, 0.93 * 8000.0);
  EXPECT_LT(closed, 1.02 * 8000.0);
}

}  // namespace
}  // namespace organfit::geometry
