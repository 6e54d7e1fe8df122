// The skeleton: medial nodes, and a shape-keeping force that is conservative, free of
// net force and torque, and indifferent to rigid motions.
#include "organfit/particles/skeleton.h"

#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <cmath>
#include <random>

#include "organfit/particles/lattice_fill.h"

namespace organfit::particles {
namespace {

struct Body {
  Positions rest;
  double a;
};

Body elongated_body() {
  CohesionParams p;
  p.r0_mm = 2.0;
  const double a = fcc_equilibrium_spacing(LennardJones(p));
  return {fill_ellipsoid({40, 16, 16}, {1, 2, 3}, a), a};
}

TEST(MedialSkeleton, NodesLieAlongTheLongAxisOfAnEllipsoid) {
  const Body b = elongated_body();
  const Skeleton s = medial_skeleton(b.rest, b.a, 6.0);
  ASSERT_GE(s.node_count(), 3);
  double min_x = 1e9, max_x = -1e9;
  for (int k = 0; k < s.node_count(); ++k) {
    const Eigen::Vector3d n = s.nodes_mm.col(k) - Eigen::Vector3d(1, 2, 3);
    EXPECT_LT(std::hypot(n.y(), n.z()), 4.0) << "node " << k << " off the axis: " << n.transpose();
    min_x = std::min(min_x, n.x()), max_x = std::max(max_x, n.x());
  }
  // The medial axis of this spheroid spans |x| <= 20 - 8^2/20 = 16.8 mm.
  EXPECT_GT(max_x - min_x, 18.0);
  EXPECT_LT(max_x - min_x, 34.0);
}

/// A spheroid of semi-axes 20, 8, 8 mm about (1, 2, 3) mm as a segmentation on `g`.
geometry::LabelVolume spheroid_mask(const geometry::ImageGeometry& g) {
  geometry::LabelVolume mask(g);
  for (int k = 0; k < g.size[2]; ++k)
    for (int j = 0; j < g.size[1]; ++j)
      for (int i = 0; i < g.size[0]; ++i) {
        const Eigen::Vector3d p =
            g.index_to_physical(Eigen::Vector3d(i, j, k)) - Eigen::Vector3d(1, 2, 3);
        mask.at(i, j, k) =
            std::pow(p.x() / 20, 2) + std::pow(p.y() / 8, 2) + std::pow(p.z() / 8, 2) < 1;
      }
  return mask;
}

/// The spheroid's grid: anisotropic and CT-like (1 x 1 x 2 mm), the organ a voxel or more
/// from every edge.
geometry::ImageGeometry spheroid_grid() {
  geometry::ImageGeometry g;
  g.size = {50, 26, 14};
  g.spacing_mm = Eigen::Vector3d(1, 1, 2);
  g.origin_mm = Eigen::Vector3d(1 - 24.5, 2 - 12.5, 3 - 13);
  return g;
}

TEST(MedialSkeleton, FromAMaskNodesLieAlongTheLongAxisOfAnEllipsoid) {
  // The same spheroid as a segmentation.
  const geometry::ImageGeometry g = spheroid_grid();
  const Skeleton s = medial_skeleton(spheroid_mask(g), 6.0);
  ASSERT_GE(s.node_count(), 3);
  double min_x = 1e9, max_x = -1e9;
  for (int k = 0; k < s.node_count(); ++k) {
    const Eigen::Vector3d n = s.nodes_mm.col(k) - Eigen::Vector3d(1, 2, 3);
    EXPECT_LT(std::hypot(n.y(), n.z()), 4.0) << "node " << k << " off the axis: " << n.transpose();
    min_x = std::min(min_x, n.x()), max_x = std::max(max_x, n.x());
  }
  EXPECT_GT(max_x - min_x, 18.0);  // the medial axis spans |x| <= 16.8 mm
  EXPECT_LT(max_x - min_x, 34.0);
  EXPECT_THROW(medial_skeleton(geometry::LabelVolume(g), 6.0), std::invalid_argument);  // empty
}

TEST(MedialSkeleton, FromAMaskDoesNotDependOnTheGridAroundTheOrgan) {
  // The spheroid above on a grid of empty margins (7 voxels below, 3 above along each axis)
  // whose axes run the other way in x and y (a patient lying prone): the organ's box is what
  // is read, and the nodes are placed in patient space.
  const geometry::ImageGeometry g = spheroid_grid();
  geometry::ImageGeometry wide = g;
  wide.size = {60, 36, 24};
  wide.direction = Eigen::Vector3d(-1, -1, 1).asDiagonal();
  wide.origin_mm = Eigen::Vector3d(1 + 24.5 + 7, 2 + 12.5 + 7, 3 - 13 - 14);
  const Skeleton a = medial_skeleton(spheroid_mask(g), 6.0),
                 b = medial_skeleton(spheroid_mask(wide), 6.0);
  ASSERT_EQ(spheroid_mask(g).count(1), spheroid_mask(wide).count(1));
  ASSERT_EQ(a.node_count(), b.node_count());
  // The same medial voxels; the first node (the deepest, ties to the lowest index) may be
  // another of equal depth, as index order runs the other way: every node of one lies
  // within a voxel's diagonal of the other's medial axis, each node of b near one of a.
  for (int k = 0; k < b.node_count(); ++k) {
    double nearest = 1e9;
    for (int m = 0; m < a.node_count(); ++m)
      nearest = std::min(nearest, (a.nodes_mm.col(m) - b.nodes_mm.col(k)).norm());
    EXPECT_LT(nearest, 6.0) << "node " << k << " at " << b.nodes_mm.col(k).transpose();
    const Eigen::Vector3d n = b.nodes_mm.col(k) - Eigen::Vector3d(1, 2, 3);
    EXPECT_LT(std::hypot(n.y(), n.z()), 4.0) << "node " << k << " off the axis";
  }
}

TEST(MedialSkeleton, ABodyTooThinForAnAxisGetsOneNode) {
  const Positions two = (Positions(3, 2) << 0, 1, 0, 0, 0, 0).finished();
  EXPECT_EQ(medial_skeleton(two, 1.0, 3.0).node_count(), 1);
  EXPECT_THROW(medial_skeleton(two, 0.0, 3.0), std::invalid_argument);
}

class SkeletonForceTest : public ::testing::Test {
 protected:
  void SetUp() override {
    body_ = elongated_body();
    skeleton_ = medial_skeleton(body_.rest, body_.a, 6.0);
    params_.stiffness = 3.0;
    params_.overlap_mm = 1.0;
  }
  State deformed(unsigned seed, double amplitude) const {
    State s(body_.rest);
    std::mt19937 rng(seed);
    std::normal_distribution<double> g(0, amplitude);
    for (int i = 0; i < s.size(); ++i)
      for (int d = 0; d < 3; ++d)
        s.x(d, i) += g(rng);
    // and a bend, so clusters turn differently
    for (int i = 0; i < s.size(); ++i)
      s.x(1, i) += 0.01 * s.x(0, i) * s.x(0, i);
    return s;
  }
  Body body_;
  Skeleton skeleton_;
  SkeletonParams params_;
};

TEST_F(SkeletonForceTest, ClustersOverlapAndCoverEveryParticle) {
  SkeletonForce force(skeleton_, body_.rest, params_);
  int total = 0;
  for (int size : force.cluster_sizes()) {
    EXPECT_GT(size, 3);
    total += size;
  }
  EXPECT_GT(total, body_.rest.cols());  // overlap: some particles in two clusters
  EXPECT_GE(force.skeleton().edges.size(), static_cast<size_t>(skeleton_.node_count() - 1));
}

TEST_F(SkeletonForceTest, ForceIsMinusEnergyGradientByFiniteDifferences) {
  SkeletonForce force(skeleton_, body_.rest, params_);
  State s = deformed(1, 0.3);
  Forces f = Forces::Zero(3, s.size());
  force.add_forces(s, f, false);
  const double h = 1e-6;
  for (int i = 0; i < s.size(); i += 37) {
    for (int d = 0; d < 3; ++d) {
      State plus = s, minus = s;
      plus.x(d, i) += h;
      minus.x(d, i) -= h;
      Forces scratch = Forces::Zero(3, s.size());
      const double ep = force.add_forces(plus, scratch, true);
      const double em = force.add_forces(minus, scratch, true);
      EXPECT_NEAR(f(d, i), -(ep - em) / (2 * h), 1e-5 * (1 + std::abs(f(d, i)))) << i << "," << d;
    }
  }
}

TEST_F(SkeletonForceTest, NoNetForceNoNetTorque) {
  SkeletonForce force(skeleton_, body_.rest, params_);
  State s = deformed(2, 0.5);
  Forces f = Forces::Zero(3, s.size());
  force.add_forces(s, f, false);
  const double scale = f.cwiseAbs().maxCoeff();
  ASSERT_GT(scale, 0.1);
  EXPECT_LT(f.rowwise().sum().norm(), 1e-9 * scale * s.size());
  Eigen::Vector3d torque = Eigen::Vector3d::Zero();
  for (int i = 0; i < s.size(); ++i)
    torque += s.x.col(i).cross(f.col(i));
  EXPECT_LT(torque.norm(), 1e-8 * scale * s.size() * 20);
}

TEST_F(SkeletonForceTest, RigidMotionCostsNothingAndTheNodesFollowIt) {
  SkeletonForce force(skeleton_, body_.rest, params_);
  const Eigen::Matrix3d r =
      Eigen::AngleAxisd(0.7, Eigen::Vector3d(1, -2, 0.5).normalized()).toRotationMatrix();
  const Eigen::Vector3d t(10, -4, 7);
  State s((r * body_.rest).colwise() + t);
  Forces f = Forces::Zero(3, s.size());
  EXPECT_NEAR(force.add_forces(s, f, true), 0.0, 1e-18 * s.size());
  EXPECT_LT(f.cwiseAbs().maxCoeff(), 1e-10);
  const Eigen::Matrix3Xd moved = (r * force.node_positions(body_.rest)).colwise() + t;
  EXPECT_LT((force.node_positions(s.x) - moved).cwiseAbs().maxCoeff(), 1e-10);
}

TEST_F(SkeletonForceTest, NewRestShapeRemovesTheRestoringForce) {
  SkeletonForce force(skeleton_, body_.rest, params_);
  State s = deformed(3, 0.4);
  Forces f = Forces::Zero(3, s.size());
  EXPECT_GT(force.add_forces(s, f, true), 1.0);
  force.set_rest_shape(s.x);
  f.setZero();
  EXPECT_NEAR(force.add_forces(s, f, true), 0.0, 1e-18 * s.size());
}

TEST_F(SkeletonForceTest, InvalidParametersAreRefused) {
  SkeletonParams bad = params_;
  bad.stiffness = 0;
  EXPECT_THROW(SkeletonForce(skeleton_, body_.rest, bad), std::invalid_argument);
  bad = params_;
  bad.overlap_mm = -1;
  EXPECT_THROW(SkeletonForce(skeleton_, body_.rest, bad), std::invalid_argument);
  EXPECT_THROW(SkeletonForce(Skeleton{}, body_.rest, params_), std::invalid_argument);
}

}  // namespace
}  // namespace organfit::particles
