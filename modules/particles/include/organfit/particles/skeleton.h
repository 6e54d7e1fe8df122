#pragma once
// The skeleton: what keeps the organ's global shape (paper s.2.1, Amrani et al. [1];
// METHOD.md s.3).
//
// Why it is needed: a Lennard-Jones body that flows (random packing, thermal
// agitation, large deformations during a fit) rounds up under its own surface tension.
// A damped crystal at zero temperature is a solid and does not.
//
// Design: a medial skeleton with frames ("shape matching", Mueller et al. 2005, over
// skeleton nodes instead of a mesh).
//  * Nodes n_k lie on the medial axis of the body at rest: ridge points of the depth
//    (distance to the surface), sampled `node_spacing` apart. They come from the
//    particles (medial_skeleton) or from a segmentation's distance map (CT stage).
//  * Each particle i is tied to the nearest node and to every node nearly as near
//    (within `overlap_mm` more): clusters C_k overlap, so neighbouring parts of the
//    body cannot slide past each other. w_i = 1 / (number of clusters of i).
//  * Each node carries a frame: its centre c_k is the weighted centroid of its cluster,
//    its rotation R_k the best rigid fit of the cluster's rest offsets q_i = x0_i - c0_k
//    onto the current ones (polar part of A_k = sum_i w_i (x_i - c_k) q_i^T).
//  * Energy and force, with g_ik = R_k q_i + c_k the goal of particle i in frame k:
//        E = k_s/2 sum_k sum_{i in C_k} w_i |g_ik - x_i|^2,
//        F_i = k_s sum_{k : i in C_k} w_i (g_ik - x_i)   (exactly -dE/dx_i: c_k and R_k
//                                                         are optimal, so their own
//                                                         variations drop out).
//    Forces sum to zero and exert no torque: the skeleton moves and turns with the body
//    at no cost, and resists only changes of shape, with stiffness k_s per particle.
//  * The nodes are not extra particles: they move with their clusters by construction,
//    so the skeleton follows the body when data forces act. A fit that should let the
//    organ flow changes the rest shape (set_rest_shape) instead of fighting it.
#include <utility>
#include <vector>

#include "organfit/geometry/image_geometry.h"
#include "organfit/particles/model.h"

namespace organfit::particles {

struct Skeleton {
  Eigen::Matrix3Xd nodes_mm;               ///< rest positions of the nodes
  std::vector<std::pair<int, int>> edges;  ///< nodes whose clusters share particles
  int node_count() const { return static_cast<int>(nodes_mm.cols()); }
};

/// Medial nodes of a particle body at rest: surface particles are those with fewer
/// than 12 neighbours within 1.2 a_nn (fcc bulk has 12); depth is the Euclidean
/// distance to the nearest surface particle (its feature); a particle is medial when a neighbour's
/// nearest surface particle lies farther than max(3 a_nn, 1.5 depth) from its own (the two surface
/// points subtend > ~97 degrees). Nodes are medial particles chosen farthest-first from the
/// deepest, at least `node_spacing_mm` apart (one node, at the deepest particle, for bodies too
/// thin to have a medial axis). Edges are left empty (SkeletonForce fills them).
Skeleton medial_skeleton(const Positions& rest, double a_nn_mm, double node_spacing_mm);

/// The same from a segmentation (label != 0 inside; the CT stage's organ mask): voxel
/// centres stand for the particles, face neighbours for the first shell, voxels with a
/// face neighbour outside for the surface, and lambda is at least two voxels; the depths
/// and features come from the exact distance transform's passes (linear in the voxels,
/// over the inside voxels' box; of equidistant surface voxels one is taken). A mask's
/// surface is the organ's own, not a particle lattice's, so its medial axis does not
/// depend on how the body was filled. Throws std::invalid_argument on an empty mask or a
/// non-positive node spacing.
Skeleton medial_skeleton(const geometry::LabelVolume& mask, double node_spacing_mm);

struct SkeletonParams {
  double stiffness = 1.0;   ///< k_s (energy / mm^2): pull of a particle towards its goal
  double overlap_mm = 1.0;  ///< how much farther than its nearest node a particle may be
                            ///< from another node and still be tied to it
};

class SkeletonForce : public ForceTerm {
 public:
  /// Ties the particles at `rest` to the skeleton's nodes. Throws std::invalid_argument
  /// on a skeleton without nodes, a non-positive stiffness or a negative overlap.
  SkeletonForce(const Skeleton& skeleton, const Positions& rest, const SkeletonParams& params);

  std::string name() const override { return "skeleton"; }
  double add_forces(const State& state, Forces& f, bool want_energy) override;
  double stiffness() const override { return params_.stiffness; }

  /// The skeleton with its edges (clusters sharing particles).
  const Skeleton& skeleton() const { return skeleton_; }
  /// Current node positions: the centroids of their clusters (mm).
  Eigen::Matrix3Xd node_positions(const Positions& x) const;
  /// Makes `rest` the new undeformed shape (same particles), e.g. to let a fit flow.
  void set_rest_shape(const Positions& rest);
  /// Cluster sizes, for reports.
  std::vector<int> cluster_sizes() const;

 private:
  /// A node's cluster: its members (ascending particle index) and, for each, where that
  /// membership is stored in memberships_.
  struct Cluster {
    std::vector<int> members;
    std::vector<int> entries;
    double weight_sum = 0;
  };
  /// One membership of a particle: cluster k, the particle's weight in it (one over its
  /// number of clusters) and its rest offset q_i = x0_i - c0 (mm). Stored by particle, so
  /// that gathering a particle's pulls reads one contiguous run.
  struct Membership {
    int cluster;
    double weight;
    Eigen::Vector3d offset;
  };
  void compute_offsets(const Positions& rest);
  Skeleton skeleton_;
  SkeletonParams params_;
  std::vector<Cluster> clusters_;
  // The clusters by particle (particle i's memberships are [first_[i], first_[i + 1]), in
  // ascending cluster order): forces are gathered per particle, in parallel, adding the
  // clusters' pulls in the order a scan of the clusters would.
  std::vector<int> first_;
  std::vector<Membership> memberships_;
  std::vector<double> energies_;  // per particle, when asked for
  std::vector<Eigen::Vector3d> centres_;
  std::vector<Eigen::Matrix3d> rotations_;
};

}  // namespace organfit::particles
