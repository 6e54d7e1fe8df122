// EmbeddedBody: the reference body moved with the particles. At rest it is the
// reference; affine motion of the particles (or a global map) moves it exactly.
#include "organfit/fitting/embedded_body.h"

#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <Eigen/LU>
#include <algorithm>
#include <cmath>
#include <random>

#include "organfit/fitting/spread_force.h"
#include "organfit/geometry/mask_ops.h"
#include "organfit/particles/cohesion.h"

namespace organfit::fitting {
namespace {

constexpr double kSpacing = 3.0;  // particle spacing (mm)

const Eigen::Vector3d kSemiAxes(20, 14, 11);  // the ellipsoid's (mm)

/// An ellipsoid of semi-axes kSemiAxes centred at c, as a mask on grid g.
std::shared_ptr<const geometry::LabelVolume> ellipsoid_on(const geometry::ImageGeometry& g,
                                                          const Eigen::Vector3d& c) {
  const Eigen::Vector3d& semi = kSemiAxes;
  auto mask = std::make_shared<geometry::LabelVolume>(g);
  for (int k = 0; k < g.size[2]; ++k)
    for (int j = 0; j < g.size[1]; ++j)
      for (int i = 0; i < g.size[0]; ++i) {
        const Eigen::Vector3d p = g.index_to_physical(Eigen::Vector3d(i, j, k)) - c;
        mask->at(i, j, k) = p.cwiseQuotient(semi).squaredNorm() <= 1.0;
      }
  return mask;
}

/// The same as a mask of 0.75 mm voxels.
std::shared_ptr<const geometry::LabelVolume> ellipsoid_mask(const Eigen::Vector3d& c) {
  return ellipsoid_on(geometry::grid_covering({c - kSemiAxes, c + kSemiAxes}, 0.75, 3.0), c);
}

/// Particles on a cubic lattice inside the mask, at least half a spacing in.
particles::Positions fill(const geometry::LabelVolume& mask) {
  const geometry::Aabb b = mask.geometry.bounds_mm();
  std::vector<Eigen::Vector3d> pts;
  for (double z = b.min_mm.z(); z <= b.max_mm.z(); z += kSpacing)
    for (double y = b.min_mm.y(); y <= b.max_mm.y(); y += kSpacing)
      for (double x = b.min_mm.x(); x <= b.max_mm.x(); x += kSpacing) {
        const Eigen::Vector3d p(x, y, z);
        bool deep = true;
        for (int d = 0; d < 3 && deep; ++d)
          for (double s : {-0.5, 0.5})
            deep = deep &&
                   geometry::inside_interpolated(mask, p + s * kSpacing * Eigen::Vector3d::Unit(d));
        if (deep) pts.push_back(p);
      }
  particles::Positions x(3, static_cast<Eigen::Index>(pts.size()));
  for (size_t i = 0; i < pts.size(); ++i)
    x.col(static_cast<Eigen::Index>(i)) = pts[i];
  return x;
}

/// The ellipsoid on a grid of 1 x 1 x 3 mm voxels (thick slices, as a CT's) with
/// `margin_mm` about it, its volume there and the particles filling it.
struct ThickSliceOrgan {
  const Eigen::Vector3d c{0.4, -0.3, 1.1};
  geometry::ImageGeometry grid;
  std::shared_ptr<const geometry::LabelVolume> mask;
  double planned_mm3 = 0;
  particles::Positions x0;
  explicit ThickSliceOrgan(double margin_mm)
      : grid(geometry::grid_covering({c - kSemiAxes, c + kSemiAxes}, 1.0, margin_mm)) {
    grid.spacing_mm.z() = 3.0;
    grid.size[2] = (grid.size[2] + 2) / 3;
    mask = ellipsoid_on(grid, c);
    planned_mm3 = mask->volume_mm3(1);
    x0 = fill(*mask);
  }
};

TEST(EmbeddedBody, AtRestIsTheReference) {
  const Eigen::Vector3d c(10, -5, 30);
  const auto mask = ellipsoid_mask(c);
  const particles::Positions x = fill(*mask);
  const EmbeddedBody body(mask, GlobalMap{}, x, x, embedding_support_mm(kSpacing));
  // At every voxel centre of the reference's grid, the reference's own label.
  const auto& g = mask->geometry;
  int agree = 0, tried = 0;
  for (int k = 0; k < g.size[2]; k += 2)
    for (int j = 0; j < g.size[1]; j += 2)
      for (int i = 0; i < g.size[0]; i += 2, ++tried)
        agree +=
            body.inside(g.index_to_physical(Eigen::Vector3d(i, j, k))) == (mask->at(i, j, k) == 1);
  EXPECT_EQ(agree, tried);
  const double v_ref = mask->volume_mm3(1), v = body.volume_mm3(0.75);
  EXPECT_NEAR(v / v_ref, 1.0, 0.01);
  EXPECT_NEAR(v_ref, 4.0 / 3.0 * M_PI * 20 * 14 * 11, 0.02 * v_ref);
}

TEST(EmbeddedBody, FollowsAnAffineMotionOfTheParticlesExactly) {
  const Eigen::Vector3d c(0, 0, 0);
  const auto mask = ellipsoid_mask(c);
  const particles::Positions x0 = fill(*mask);
  Eigen::Matrix3d a;
  a << 1.2, 0.1, 0.0, -0.05, 0.9, 0.08, 0.02, 0.0, 0.95;
  const Eigen::Vector3d t(3, -2, 1.5);
  const particles::Positions x1 = (a * x0).colwise() + t;
  const EmbeddedBody body(mask, GlobalMap{}, x0, x1, embedding_support_mm(kSpacing));
  // Pulled back through the moving-least-squares field: exact for affine motion, also
  // beyond the outermost particles (on and just outside the surface).
  for (const Eigen::Vector3d& r :
       {Eigen::Vector3d(0, 0, 0), Eigen::Vector3d(19.5, 0, 0), Eigen::Vector3d(0, -14.2, 0),
        Eigen::Vector3d(8, 7, -8), Eigen::Vector3d(-12, 3, 8.5)}) {
    const Eigen::Vector3d q = a * r + t;
    EXPECT_LT((body.pull_back(q) - r).norm(), 1e-6) << r.transpose();
  }
  EXPECT_NEAR(body.volume_mm3(0.75) / (mask->volume_mm3(1) * a.determinant()), 1.0, 0.01);
}

TEST(EmbeddedBody, AppliesTheGlobalMapsInverse) {
  const auto mask = ellipsoid_mask(Eigen::Vector3d::Zero());
  const particles::Positions x0 = fill(*mask);
  GlobalMap map;
  map.affine.a = Eigen::Vector3d(1.3, 1 / std::sqrt(1.3), 1 / std::sqrt(1.3)).asDiagonal();
  map.affine.t = Eigen::Vector3d(1, 2, 3);
  map.shears.c(3) = 0.004;  // y += 0.004 u_x^2: a bend
  particles::Positions placed(3, x0.cols());
  for (Eigen::Index i = 0; i < x0.cols(); ++i)
    placed.col(i) = map.apply(x0.col(i));
  const EmbeddedBody body(mask, map, placed, placed, embedding_support_mm(kSpacing));
  for (const Eigen::Vector3d& r :
       {Eigen::Vector3d(15, 2, 1), Eigen::Vector3d(-19.5, 0, 0), Eigen::Vector3d(0, 13.8, 0)})
    EXPECT_LT((body.pull_back(map.apply(r)) - r).norm(), 1e-9);
  // Volume-preserving map: the same volume.
  EXPECT_NEAR(body.volume_mm3(0.75) / mask->volume_mm3(1), 1.0, 0.01);
}

// on_grid sets blocks far from the surface without evaluating their voxels: the labels
// are exactly those of evaluating inside() at every voxel, on a rotated, anisotropic grid,
// under a global map with shears, fields and a flow and a local push the particles carry.
TEST(EmbeddedBody, OnGridIsEveryVoxelsInsideTest) {
  const auto mask = ellipsoid_mask(Eigen::Vector3d(3, -2, 5));
  const particles::Positions x0 = fill(*mask);
  GlobalMap map;
  map.affine.a = Eigen::AngleAxisd(0.2, Eigen::Vector3d::UnitZ()).toRotationMatrix() *
                 Eigen::Vector3d(1.1, 1 / 1.1, 1.0).asDiagonal();
  map.affine.t = Eigen::Vector3d(1, -2, 0.5);
  map.shears.centre = Eigen::Vector3d(3, -2, 5);
  map.shears.c(3) = 0.004, map.shears.c(10) = -0.003;
  map.fields = ShearFields::over({-20, -18, -8}, {26, 14, 18}, 8.0);
  std::mt19937 rng(3);
  std::normal_distribution<double> g(0.0, 0.6);
  for (Eigen::Index i = 0; i < map.fields.weights.size(); ++i)
    map.fields.weights(i) = g(rng);
  map.flow = IncompressibleFlow::over({-20, -18, -8}, {26, 14, 18}, 10.0);
  for (Eigen::Index i = 0; i < map.flow.potentials.size(); ++i)
    map.flow.potentials(i) = g(rng);
  particles::Positions placed(3, x0.cols()), current(3, x0.cols());
  for (Eigen::Index i = 0; i < x0.cols(); ++i) {
    placed.col(i) = map.apply(x0.col(i));
    const double push =
        2.5 * std::exp(-(placed.col(i) - Eigen::Vector3d(20, 0, 5)).squaredNorm() / 80);
    current.col(i) = placed.col(i) - push * Eigen::Vector3d::UnitX();  // a dent from +x
  }
  const EmbeddedBody body(mask, map, placed, current, embedding_support_mm(kSpacing));
  geometry::ImageGeometry grid = geometry::grid_covering(body.bounds(), 0.6, 2.0);
  grid.spacing_mm = Eigen::Vector3d(0.6, 0.5, 1.1);
  grid.size = {static_cast<int>(grid.size[0] * 1.4), static_cast<int>(grid.size[1] * 1.4),
               static_cast<int>(grid.size[2] * 0.8)};
  grid.direction = Eigen::AngleAxisd(0.4, Eigen::Vector3d(1, 1, 0).normalized()).toRotationMatrix();
  const Eigen::Vector3d middle = 0.5 * (body.bounds().min_mm + body.bounds().max_mm);
  grid.origin_mm = middle - grid.direction *
                                grid.spacing_mm.cwiseProduct(Eigen::Vector3d(
                                    grid.size[0] - 1, grid.size[1] - 1, grid.size[2] - 1)) /
                                2;
  const geometry::LabelVolume labels = body.on_grid(grid);
  long long inside = 0, differ = 0;
#pragma omp parallel for reduction(+ : inside, differ) schedule(dynamic, 1)
  for (int k = 0; k < grid.size[2]; ++k)
    for (int j = 0; j < grid.size[1]; ++j)
      for (int i = 0; i < grid.size[0]; ++i) {
        const bool in = body.inside(grid.index_to_physical(Eigen::Vector3d(i, j, k)));
        inside += in;
        differ += in != (labels.at(i, j, k) == 1);
      }
  EXPECT_EQ(differ, 0);
  EXPECT_GT(inside, 10000);  // the organ is on the grid
}

// Moved rigidly by part of a voxel and counted on its own grid (1 x 1 x 3 mm), the organ
// keeps its voxel count on average over the shifts (the expected count on a shifted grid is
// the volume of the region sampled: at the zero level of its signed distance 2.2% short),
// and no shift loses a layer of voxels (exactly half a slice along z tied at every
// boundary at the zero level: -10%).
TEST(EmbeddedBody, KeepsItsVoxelCountOnItsGridMovedByPartOfAVoxel) {
  const ThickSliceOrgan organ(4.0);
  std::mt19937 rng(11);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  std::vector<Eigen::Vector3d> shifts = {{0.5, 0, 0}, {0, 0, 0.5}, {0.3, 0.7, 0.4}};
  while (shifts.size() < 64)
    shifts.emplace_back(u(rng), u(rng), u(rng));
  double sum = 0;
  for (const Eigen::Vector3d& s : shifts) {
    GlobalMap map;
    map.affine.t = s.cwiseProduct(organ.grid.spacing_mm);
    const particles::Positions placed = organ.x0.colwise() + map.affine.t;
    const EmbeddedBody body(organ.mask, map, placed, placed, embedding_support_mm(kSpacing));
    const double ratio = body.on_grid(organ.grid).volume_mm3(1) / organ.planned_mm3;
    EXPECT_GT(ratio, 0.95) << s.transpose();
    sum += ratio;
  }
  EXPECT_NEAR(sum / static_cast<double>(shifts.size()), 1.0, 0.005);
}

// Counted on copies of a thick-slice grid (1 x 1 x 3 mm) moved by parts of a voxel, an
// organ stretched 1.15x with its volume kept averages to its volume; the counts spread by
// more than independent half-voxel errors at the boundary voxels would (the export's volume
// check, pipeline/export_stage.cpp, compares their mean for that reason).
TEST(EmbeddedBody, VolumesOnShiftedGridsAverageToItsVolume) {
  const ThickSliceOrgan organ(8.0);
  GlobalMap map;
  const double s = 1.15;
  map.affine.a = Eigen::Vector3d(1 / std::sqrt(s), 1 / std::sqrt(s), s).asDiagonal();
  // About the organ's centre: it stays on the grid.
  map.affine.t = organ.c - map.affine.a * organ.c;
  particles::Positions placed(3, organ.x0.cols());
  for (Eigen::Index i = 0; i < organ.x0.cols(); ++i)
    placed.col(i) = map.apply(organ.x0.col(i));
  const EmbeddedBody body(organ.mask, map, placed, placed, embedding_support_mm(kSpacing));
  const std::vector<double> v = body.volumes_on_shifted_grids(organ.grid, 16);
  ASSERT_EQ(v.size(), 16u);
  double mean = 0, square = 0;
  for (const double x : v)
    mean += x / 16;
  for (const double x : v)
    square += (x - mean) * (x - mean);
  const double sd = std::sqrt(square / 15);
  EXPECT_NEAR(mean / organ.planned_mm3, 1.0, 3 * sd / 4 / organ.planned_mm3);
  long long boundary = 0;
  for (const auto b : geometry::surface_of(body.on_grid(organ.grid)))
    boundary += b;
  EXPECT_GT(sd, 0.5 * organ.grid.spacing_mm.prod() * std::sqrt(static_cast<double>(boundary)));
  // The first copy: moved by (1/2, 1/3, 1/5) of a voxel less half a voxel along each axis.
  geometry::ImageGeometry first = organ.grid;
  first.origin_mm +=
      organ.grid.spacing_mm.cwiseProduct(Eigen::Vector3d(0, 1.0 / 3 - 0.5, 0.2 - 0.5));
  EXPECT_EQ(v[0], body.on_grid(first).volume_mm3(1));
  EXPECT_TRUE(body.volumes_on_shifted_grids(organ.grid, 0).empty());
  EXPECT_THROW(body.volumes_on_shifted_grids(organ.grid, -1), std::invalid_argument);
}

// A part of the organ no particle fills (an island of a few voxels 16 mm beyond the
// ellipsoid, a stray of the contouring or a node): at rest the body on its grid is the
// reference voxel for voxel, the island included; under a global map with a bend the
// island is where the map puts it, whole. The particles' box had bounded the body, and the
// island was left out of the exported organ (even at rest).
TEST(EmbeddedBody, HoldsThePartsOfTheOrganNoParticleFills) {
  const Eigen::Vector3d c(0, 0, 0), island(36, 0, 0);
  const geometry::ImageGeometry g =
      geometry::grid_covering({c - kSemiAxes, island + Eigen::Vector3d::Constant(2)}, 0.75, 3.0);
  auto mask = std::make_shared<geometry::LabelVolume>(*ellipsoid_on(g, c));
  const particles::Positions x0 = fill(*mask);  // before the island: none in it
  int island_voxels = 0;
  for (int k = 0; k < g.size[2]; ++k)
    for (int j = 0; j < g.size[1]; ++j)
      for (int i = 0; i < g.size[0]; ++i)
        if ((g.index_to_physical(Eigen::Vector3d(i, j, k)) - island).norm() <= 1.6)
          mask->at(i, j, k) = 1, ++island_voxels;
  ASSERT_GT(island_voxels, 20);
  ASSERT_LT(x0.row(0).maxCoeff() + embedding_support_mm(kSpacing), island.x() - 2);

  const EmbeddedBody at_rest(mask, GlobalMap{}, x0, x0, embedding_support_mm(kSpacing));
  const geometry::LabelVolume same = at_rest.on_grid(g);
  EXPECT_TRUE(same.labels == mask->labels);

  GlobalMap map;
  map.affine.a = Eigen::Vector3d(1.1, 1 / std::sqrt(1.1), 1 / std::sqrt(1.1)).asDiagonal();
  map.affine.t = Eigen::Vector3d(2, -1, 0.5);
  map.shears.c(3) = 0.004;  // y += 0.004 u_x^2: a bend
  particles::Positions placed(3, x0.cols());
  for (Eigen::Index i = 0; i < x0.cols(); ++i)
    placed.col(i) = map.apply(x0.col(i));
  const EmbeddedBody moved(mask, map, placed, placed, embedding_support_mm(kSpacing));
  const geometry::ImageGeometry today = geometry::grid_covering(moved.bounds(), 0.5, 0.0);
  const geometry::LabelVolume organ = moved.on_grid(today);
  const Eigen::Vector3d there = map.apply(island);
  int at_island = 0;
  for (int k = 0; k < today.size[2]; ++k)
    for (int j = 0; j < today.size[1]; ++j)
      for (int i = 0; i < today.size[0]; ++i)
        if (organ.at(i, j, k) &&
            (today.index_to_physical(Eigen::Vector3d(i, j, k)) - there).norm() < 3)
          ++at_island;
  // The island's volume (the voxels' 0.42 mm3 each) on the finer grid: kept to 20%.
  EXPECT_NEAR(at_island * 0.125, island_voxels * mask->geometry.spacing_mm.prod(),
              0.2 * island_voxels * mask->geometry.spacing_mm.prod());
}

TEST(EmbeddedBody, IsEmptyFarFromTheParticlesAndRefusesBadInput) {
  const auto mask = ellipsoid_mask(Eigen::Vector3d::Zero());
  const particles::Positions x = fill(*mask);
  const EmbeddedBody body(mask, GlobalMap{}, x, x, embedding_support_mm(kSpacing));
  // Far from the particles the map is the global one (here the identity).
  EXPECT_EQ(body.pull_back(Eigen::Vector3d(500, 0, 0)), Eigen::Vector3d(500, 0, 0));
  EXPECT_FALSE(body.inside(Eigen::Vector3d(500, 0, 0)));
  EXPECT_FALSE(body.inside(Eigen::Vector3d(std::nan(""), 0, 0)));
  EXPECT_FALSE(body.inside(Eigen::Vector3d(1e300, -1e300, 0)));
  EXPECT_THROW(EmbeddedBody(mask, GlobalMap{}, x, x.leftCols(3), 5.0), std::invalid_argument);
  EXPECT_THROW(EmbeddedBody(mask, GlobalMap{}, x, x, 0.0), std::invalid_argument);
  particles::Positions bad = x;
  bad(0, 0) = std::nan("");
  EXPECT_THROW(EmbeddedBody(mask, GlobalMap{}, bad, x, 5.0), std::invalid_argument);
  // A particle flung 3 m away: no grid over that is made.
  particles::Positions flung = x;
  flung(1, 0) = 3000;
  EXPECT_THROW(EmbeddedBody(mask, GlobalMap{}, x, flung, 5.0), std::invalid_argument);
}

TEST(SurfaceFeet, AreTheNearestSamplesWithTheirNormalsWithinTheReach) {
  // Samples on the plane z = 0 (0.5 mm apart), normal +z; particles below it.
  SurfaceSamples plane;
  plane.points.resize(3, 41 * 41);
  plane.normals.resize(3, 41 * 41);
  for (int j = 0, k = 0; j < 41; ++j)
    for (int i = 0; i < 41; ++i, ++k)
      plane.points.col(k) = Eigen::Vector3d(-10 + 0.5 * i, -10 + 0.5 * j, 0),
      plane.normals.col(k) = Eigen::Vector3d::UnitZ();
  particles::Positions x(3, 3);
  x.col(0) = Eigen::Vector3d(0.25, 0, -1.5);  // between two samples: the first is taken
  x.col(1) = Eigen::Vector3d(3, -2, -0.2);
  x.col(2) = Eigen::Vector3d(0, 0, -40);
  const SurfaceFeet feet = surface_feet(x, plane, 6.0);
  EXPECT_TRUE(feet.offset_mm.col(0).isApprox(Eigen::Vector3d(-0.25, 0, 1.5), 1e-12));
  EXPECT_TRUE(feet.offset_mm.col(1).isApprox(Eigen::Vector3d(0, 0, 0.2), 1e-12));
  EXPECT_TRUE(feet.normal.col(1).isApprox(Eigen::Vector3d::UnitZ(), 1e-12));
  // Deep inside: the reach, away from the particles' centroid.
  EXPECT_NEAR(feet.offset_mm.col(2).norm(), 6.0, 1e-12);
  EXPECT_LT(feet.normal(2, 2), -0.99);
}

TEST(NearestSurfaceParticle, ReadsAPointOnTheSurfaceBesideTheFootAsOnIt) {
  // A flat organ surface z = 0 above two particles 4 mm apart, 1.5 mm deep. A point on
  // that surface 2 mm beside a foot is on the surface: the tangent plane says 0, a
  // sphere of the depth about the particle would say hypot(2, 1.5) - 1.5 = 1 mm out.
  particles::Positions x(3, 2);
  x.col(0) = Eigen::Vector3d(0, 0, -1.5);
  x.col(1) = Eigen::Vector3d(4, 0, -1.5);
  SurfaceFeet feet;
  feet.offset_mm = Eigen::Matrix3Xd::Zero(3, 2);
  feet.offset_mm.row(2).setConstant(1.5);
  feet.normal = Eigen::Matrix3Xd::Zero(3, 2);
  feet.normal.row(2).setConstant(1.0);
  const auto on = nearest_surface_particle(x, {0, 1}, Eigen::Vector3d(1.9, 0, 0), feet, 1.5);
  EXPECT_EQ(on.first, 0);
  EXPECT_NEAR(on.second, 0.0, 1e-12);
  const auto below = nearest_surface_particle(x, {0, 1}, Eigen::Vector3d(2.5, 1, -0.7), feet, 1.5);
  EXPECT_EQ(below.first, 1);
  EXPECT_NEAR(below.second, -0.7, 1e-12);  // inside: negative
  const auto balls = nearest_surface_particle(x, {0, 1}, Eigen::Vector3d(2, 0, 0), {}, 1.5);
  EXPECT_NEAR(balls.second, 1.0, 1e-12);
  // A particle 3 mm below particle 0 with its foot 0.1 mm nearer the point: the outer
  // one, whose path through its foot is shorter, takes it.
  particles::Positions stacked(3, 2);
  stacked.col(0) = Eigen::Vector3d(0, 0, -1.5);
  stacked.col(1) = Eigen::Vector3d(0.1, 0, -4.5);
  SurfaceFeet under;
  under.offset_mm = Eigen::Matrix3Xd::Zero(3, 2);
  under.offset_mm(2, 0) = 1.5, under.offset_mm(2, 1) = 4.5;
  under.normal = feet.normal;
  EXPECT_EQ(nearest_surface_particle(stacked, {1, 0}, Eigen::Vector3d(1, 0, 0.2), under, 1.5).first,
            0);
}

// The skin index answers as the scans define it, ties included: random particles (some at
// the same place, some sharing a foot), a random subset as candidates in shuffled order,
// queries near and far.
TEST(SkinIndex, AnswersAsTheScansIncludingTies) {
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> u(-20, 20), off(-2, 2);
  const int n = 600;
  particles::Positions x(3, n);
  SurfaceFeet feet;
  feet.offset_mm.resize(3, n);
  feet.normal.resize(3, n);
  for (int i = 0; i < n; ++i) {
    x.col(i) = Eigen::Vector3d(u(rng), u(rng), u(rng));
    feet.offset_mm.col(i) = Eigen::Vector3d(off(rng), off(rng), off(rng));
    feet.normal.col(i) = feet.offset_mm.col(i).normalized();
  }
  for (int i = 0; i < 40; ++i) {  // ties: the same centre, the same foot and offset
    x.col(n - 1 - i) = x.col(i);
    feet.offset_mm.col(n - 1 - i) = feet.offset_mm.col(i);
  }
  std::vector<int> candidates;
  for (int i = 0; i < n; ++i)
    if (i % 3 != 1) candidates.push_back(i);
  std::shuffle(candidates.begin(), candidates.end(), rng);
  const SkinIndex with_feet(x, candidates, &feet), balls(x, candidates);
  std::vector<int> near;
  for (int q = 0; q < 400; ++q) {
    const Eigen::Vector3d p =
        q < 40 ? Eigen::Vector3d(x.col(q)) : Eigen::Vector3d(3 * u(rng), u(rng), u(rng));
    EXPECT_EQ(with_feet.nearest_particle(p), nearest_particle(x, candidates, p));
    EXPECT_EQ(with_feet.nearest_surface_particle(p, 1.5),
              nearest_surface_particle(x, candidates, p, feet, 1.5));
    EXPECT_EQ(balls.nearest_surface_particle(p, 1.5),
              nearest_surface_particle(x, candidates, p, {}, 1.5));
    const double radius = 0.5 + 0.05 * q;
    balls.within(p, radius, near);
    std::vector<int> scan;
    for (int i : candidates)
      if ((x.col(i) - p).squaredNorm() <= radius * radius) scan.push_back(i);
    EXPECT_EQ(near, scan);
  }
  const std::vector<int> none;
  EXPECT_EQ(SkinIndex(x, none).nearest_particle(Eigen::Vector3d::Zero()).first, -1);
  EXPECT_EQ(SkinIndex(x, none, &feet).nearest_surface_particle(Eigen::Vector3d::Zero(), 1).first,
            -1);
}

TEST(SpreadAttractiveForce, PullsTheEpicentreAlongItsNormalByItsGapToThePoint) {
  // Two particles; the point is 5 mm above particle 0 and 1 mm to the side, whose surface
  // lies 1.2 mm above it (normal +z): the residual is 3.8 mm along +z, and the force on
  // particle 0 has no sideways part.
  particles::CohesionParams cp;
  cp.r0_mm = 3.0;
  const particles::LennardJones law(cp);
  particles::Positions x(3, 2);
  x.col(0) = Eigen::Vector3d(0, 0, 0);
  x.col(1) = Eigen::Vector3d(0, 0, -3);
  SpreadForceParams params;
  params.hold_volume = false;
  params.hold_pose = false;  // the pull alone (two particles: held, it would be shared)
  params.outlier_distance_mm = 20;
  params.stiffness_fraction = 1e-3;  // below the cohesion cap
  SurfaceFeet feet;
  feet.offset_mm.resize(3, 2);
  feet.offset_mm << 0, 0, 0, 0, 1.2, 1.2;
  feet.normal.resize(3, 2);
  feet.normal << 0, 0, 0, 0, 1, 1;
  SpreadAttractiveForce term({{Eigen::Vector3d(1, 0, 5), 1.0}}, law, 1.5, params, 0.5);
  term.set_surface_feet(feet);
  particles::State s(x);
  particles::Forces f = particles::Forces::Zero(3, 2);
  term.add_forces(s, f, false);
  EXPECT_EQ(term.status()[0].epicentre, 0);
  EXPECT_GT(f(2, 0), 0);
  EXPECT_NEAR(f.col(0).head<2>().norm(), 0, 1e-12);
  // With the balls' radius (1.5 mm) instead the residual is |(1, 0, 5)| - 1.5 along the
  // line to the point (below the cohesion cap).
  SpreadAttractiveForce balls({{Eigen::Vector3d(1, 0, 5), 1.0}}, law, 1.5, params, 0.5);
  particles::Forces g = particles::Forces::Zero(3, 2);
  balls.add_forces(s, g, false);
  const double r_balls = std::sqrt(26.0) - 1.5;
  EXPECT_NEAR(g(2, 0) / f(2, 0), r_balls * (5 / std::sqrt(26.0)) / 3.8, 1e-9);
  EXPECT_NEAR(g(0, 0) / g(2, 0), 0.2, 1e-9);
  feet.normal(2, 0) = 2;
  EXPECT_THROW(term.set_surface_feet(feet), std::invalid_argument);
}

}  // namespace
}  // namespace organfit::fitting
