#include "organfit/particles/skeleton.h"

#include <Eigen/LU>
#include <Eigen/SVD>
#include <algorithm>
#include <cmath>
#include <limits>
#include <set>
#include <stdexcept>
#include <string>

#include "organfit/geometry/image_geometry.h"
#include "organfit/geometry/sample_grid.h"
#include "organfit/particles/neighbour_list.h"

namespace organfit::particles {
namespace {

/// Calls visit(i, j) for each pair of `list`'s particles closer than its cutoff (each pair
/// once), on threads: `visit` must be safe to call concurrently.
template <class Visit>
void for_each_close_pair(const NeighbourList& list, const Positions& x, Visit&& visit) {
  const auto& order = list.order();
  const double reach = list.cutoff();
#pragma omp parallel for schedule(static) if (list.size() >= kParallelMinParticles)
  for (int s = 0; s < list.size(); ++s) {
    for (int k = list.first()[s]; k < list.first()[s + 1]; ++k) {
      const int i = order[s], j = order[list.neighbours()[k]];
      if ((x.col(i) - x.col(j)).norm() < reach) visit(i, j);
    }
  }
}

/// Rotation closest to A (polar decomposition through the SVD), det = +1.
Eigen::Matrix3d closest_rotation(const Eigen::Matrix3d& a) {
  Eigen::JacobiSVD<Eigen::Matrix3d> svd(a, Eigen::ComputeFullU | Eigen::ComputeFullV);
  Eigen::Matrix3d u = svd.matrixU();
  const Eigen::Matrix3d& v = svd.matrixV();
  if ((u * v.transpose()).determinant() < 0) u.col(2) *= -1;
  return u * v.transpose();
}

}  // namespace

namespace {

/// The medial nodes of a body given as sample points (particles or voxel centres):
/// `for_each_pair(visit)` calls visit(i, j) for each pair of close neighbours (possibly
/// on threads), `surface` marks the points on the body's surface, `min_lambda_mm` is the
/// sampling's own scale (see below), `box_mm` the size of the boxes the depths are searched
/// by (2 sample spacings; a speed setting only, the answers do not depend on it).
template <class ForEachPair>
Skeleton medial_nodes(const Positions& rest, ForEachPair&& for_each_pair,
                      const std::vector<char>& surface_flags, double min_lambda_mm,
                      double node_spacing_mm, double box_mm) {
  const int n = static_cast<int>(rest.cols());
  Skeleton skeleton;
  // Depth and feature: the Euclidean distance to, and index of, the nearest surface
  // point (exact, by a grid search over surface points; a graph distance through the
  // lattice is anisotropic and frays the medial axis).
  std::vector<int> surface;
  for (int i = 0; i < n; ++i)
    if (surface_flags[i]) surface.push_back(i);
  std::vector<double> depth(n, 0.0);
  std::vector<int> feature(n, -1);
  if (!surface.empty()) {
    Eigen::Matrix3Xd at(3, static_cast<Eigen::Index>(surface.size()));
    for (size_t k = 0; k < surface.size(); ++k)
      at.col(static_cast<Eigen::Index>(k)) = rest.col(surface[k]);
    // Buckets sized by the surface's extent, not by the sampling: a point deep inside
    // searches a few rings of them, where rings of sample-sized cells would be thousands.
    // The points by boxes of box_mm sharing one list of candidates: the
    // answers of a search per point (ties: the lower index), for fewer cell walks (the box
    // size sets the speed only; docs/decisions.md has the sizes measured).
    const geometry::SampleGrid nearest(at);
    const std::vector<std::pair<int, double>> found = nearest.nearest_each(rest, box_mm);
#pragma omp parallel for schedule(static) if (n >= kParallelMinParticles)
    for (int i = 0; i < n; ++i) {
      const auto [k, d2] = found[static_cast<size_t>(i)];
      depth[i] = std::sqrt(d2);
      feature[i] = surface[static_cast<size_t>(k)];
    }
  }
  // Medial: the lambda-medial axis (Chazal & Lieutier 2005), stable under surface noise.
  // A point is medial when its own nearest surface point and a neighbour's lie at least
  // 2 lambda apart (the two sides of the body meet here). lambda is a fixed fraction of
  // the body's largest depth: a depth-relative threshold lets a faceted surface grow
  // spurious branches near the surface. It is at least `min_lambda_mm`: a point one
  // layer deep is equidistant from several surface points, and neighbours picking
  // different ones have features a few sample spacings apart.
  const double max_depth = *std::max_element(depth.begin(), depth.end());
  const double lambda = std::max(min_lambda_mm, 0.4 * max_depth);
  // The test is symmetric: a pair that passes makes both its points medial.
  std::vector<char> medial(n, 0);
  for_each_pair([&](int i, int j) {
    if (feature[i] >= 0 && feature[j] >= 0 &&
        (rest.col(feature[i]) - rest.col(feature[j])).norm() >= 2 * lambda) {
#pragma omp atomic write
      medial[i] = 1;
#pragma omp atomic write
      medial[j] = 1;
    }
  });
  std::vector<int> candidates;
  for (int i = 0; i < n; ++i)
    if (medial[i]) candidates.push_back(i);
  if (candidates.empty()) {  // too thin for a medial axis: one node at the deepest point
    candidates.push_back(
        static_cast<int>(std::max_element(depth.begin(), depth.end()) - depth.begin()));
  }
  // Farthest-point sampling, starting from the deepest ridge point (lowest index on ties).
  std::vector<int> chosen;
  int start = candidates.front();
  for (int c : candidates)
    if (depth[c] > depth[start]) start = c;
  chosen.push_back(start);
  std::vector<double> gap(candidates.size(), std::numeric_limits<double>::infinity());
  for (;;) {
    int best = -1;
    double best_gap = node_spacing_mm;
    for (size_t c = 0; c < candidates.size(); ++c) {
      gap[c] = std::min(gap[c], (rest.col(candidates[c]) - rest.col(chosen.back())).norm());
      if (gap[c] >= best_gap) best_gap = gap[c], best = static_cast<int>(c);
    }
    if (best < 0) break;
    chosen.push_back(candidates[best]);
  }
  skeleton.nodes_mm.resize(3, static_cast<Eigen::Index>(chosen.size()));
  for (size_t k = 0; k < chosen.size(); ++k)
    skeleton.nodes_mm.col(k) = rest.col(chosen[k]);
  return skeleton;
}

}  // namespace

Skeleton medial_skeleton(const Positions& rest, double a_nn_mm, double node_spacing_mm) {
  if (!(a_nn_mm > 0) || !(node_spacing_mm > 0)) {
    throw std::invalid_argument("skeleton: lattice spacing and node spacing must be > 0 mm");
  }
  const int n = static_cast<int>(rest.cols());
  if (n == 0) {
    Skeleton empty;
    empty.nodes_mm.resize(3, 0);
    return empty;
  }
  // Neighbours: the first shell; surface = incomplete first shell (fcc bulk: 12).
  const double reach = 1.2 * a_nn_mm;
  NeighbourList list(reach, 1e-9 * reach);
  list.update(rest);
  auto for_each_pair = [&](auto&& visit) { for_each_close_pair(list, rest, visit); };
  std::vector<int> count(n, 0);
  for_each_pair([&](int i, int j) {
#pragma omp atomic
    ++count[i];
#pragma omp atomic
    ++count[j];
  });
  std::vector<char> surface(n, 0);
  for (int i = 0; i < n; ++i)
    surface[i] = count[i] < 12;
  // Neighbours may pick features up to a + 1.2 a + a apart: lambda >= 2 a.
  return medial_nodes(rest, for_each_pair, surface, 2.0 * a_nn_mm, node_spacing_mm, 2.0 * a_nn_mm);
}

Skeleton medial_skeleton(const geometry::LabelVolume& mask, double node_spacing_mm) {
  if (!(node_spacing_mm > 0)) throw std::invalid_argument("skeleton: node spacing must be > 0 mm");
  const auto& g = mask.geometry;
  std::vector<long long> voxel;  // inside voxels, in index order
  std::vector<int> index_of(mask.labels.size(), -1);
  for (long long v = 0; v < g.voxel_count(); ++v)
    if (mask.labels[static_cast<size_t>(v)])
      index_of[static_cast<size_t>(v)] = static_cast<int>(voxel.size()), voxel.push_back(v);
  const int n = static_cast<int>(voxel.size());
  if (n == 0) throw std::invalid_argument("skeleton: the mask is empty");
  Positions rest(3, n);
  std::vector<std::vector<int>> graph(n);
  std::vector<char> surface(n, 0);
  const long long sx = g.size[0], sxy = sx * g.size[1];
  for (int a = 0; a < n; ++a) {
    const long long v = voxel[a];
    const int i = static_cast<int>(v % sx), j = static_cast<int>((v / sx) % g.size[1]),
              k = static_cast<int>(v / sxy);
    rest.col(a) = g.index_to_physical(Eigen::Vector3d(i, j, k));
    const int idx[3] = {i, j, k};
    const long long stride[3] = {1, sx, sxy};
    for (int d = 0; d < 3; ++d)
      for (int s = -1; s <= 1; s += 2) {
        const int at = idx[d] + s;
        const int b =
            (at < 0 || at >= g.size[d]) ? -1 : index_of[static_cast<size_t>(v + s * stride[d])];
        if (b < 0)
          surface[a] = 1;  // a face neighbour outside (or off the grid)
        else
          graph[a].push_back(b);
      }
  }
  const double voxel_mm = g.spacing_mm.maxCoeff();
  auto for_each_pair = [&graph](auto&& visit) {
    for (size_t a = 0; a < graph.size(); ++a)
      for (int b : graph[a])
        visit(static_cast<int>(a), b);
  };
  // Boxes of 2 voxel spacings as the voxels' volume gives them, not 2 of their longest side:
  // 10 mm boxes on 0.78 x 0.78 x 5 mm voxels searched 0.63 s for a 1.5 L liver's 468,000
  // voxels, 2.9 mm boxes 0.18 s.
  const double box_mm = 2.0 * std::cbrt(g.spacing_mm.prod());
  return medial_nodes(rest, for_each_pair, surface, 2.0 * voxel_mm, node_spacing_mm, box_mm);
}

SkeletonForce::SkeletonForce(const Skeleton& skeleton, const Positions& rest,
                             const SkeletonParams& params)
    : skeleton_(skeleton), params_(params) {
  if (skeleton.node_count() == 0) throw std::invalid_argument("skeleton: no nodes");
  if (!(params.stiffness > 0) || !std::isfinite(params.stiffness))
    throw std::invalid_argument("skeleton: stiffness must be > 0");
  if (!(params.overlap_mm >= 0)) throw std::invalid_argument("skeleton: overlap must be >= 0 mm");
  const int n = static_cast<int>(rest.cols());
  const int nodes = skeleton.node_count();
  clusters_.assign(nodes, {});
  // Particle i belongs to the nodes within overlap_mm of its nearest node's distance, in
  // ascending node order: the nodes bucketed, the candidates a little beyond that reach,
  // each kept by the same test on |node - x_i| a scan of every node makes.
  std::vector<std::vector<int>> member_of(n);
  const geometry::SampleGrid grid(skeleton.nodes_mm);
#pragma omp parallel
  {
    std::vector<int> near;
#pragma omp for schedule(static)
    for (int i = 0; i < n; ++i) {
      const Eigen::Vector3d x = rest.col(i);
      const double nearest = (skeleton.nodes_mm.col(grid.nearest(x).first) - x).norm();
      const double reach = nearest + params.overlap_mm;
      near.clear();
      grid.within(x, reach * (1 + 1e-12) + 1e-12, near);
      for (int k : near)
        if ((skeleton.nodes_mm.col(k) - x).norm() <= reach) member_of[i].push_back(k);
    }
  }
  std::set<std::pair<int, int>> edges;
  for (int i = 0; i < n; ++i) {
    for (int k : member_of[i])
      clusters_[k].members.push_back(i);
    for (size_t a = 0; a < member_of[i].size(); ++a)
      for (size_t b = a + 1; b < member_of[i].size(); ++b)
        edges.insert({member_of[i][a], member_of[i][b]});
  }
  skeleton_.edges.assign(edges.begin(), edges.end());
  first_.assign(n + 1, 0);
  for (int i = 0; i < n; ++i)
    first_[i + 1] = first_[i] + static_cast<int>(member_of[i].size());
  memberships_.resize(first_[n]);
  std::vector<int> fill(first_.begin(), first_.end() - 1);
  for (int k = 0; k < nodes; ++k) {
    auto& c = clusters_[k];
    c.entries.resize(c.members.size());
    for (size_t m = 0; m < c.members.size(); ++m) {
      const int i = c.members[m];
      c.entries[m] = fill[i]++;
      memberships_[c.entries[m]] = {k, 1.0 / static_cast<double>(member_of[i].size()),
                                    Eigen::Vector3d::Zero()};
    }
  }
  compute_offsets(rest);
}

void SkeletonForce::compute_offsets(const Positions& rest) {
  const int clusters = static_cast<int>(clusters_.size());
#pragma omp parallel for schedule(dynamic, 16) if (rest.cols() >= kParallelMinParticles)
  for (int k = 0; k < clusters; ++k) {
    auto& c = clusters_[k];
    c.weight_sum = 0;
    Eigen::Vector3d centre = Eigen::Vector3d::Zero();
    for (size_t m = 0; m < c.members.size(); ++m) {
      const double w = memberships_[c.entries[m]].weight;
      centre += w * rest.col(c.members[m]);
      c.weight_sum += w;
    }
    if (c.weight_sum > 0) centre /= c.weight_sum;
    for (size_t m = 0; m < c.members.size(); ++m)
      memberships_[c.entries[m]].offset = rest.col(c.members[m]) - centre;
  }
  centres_.assign(clusters_.size(), Eigen::Vector3d::Zero());
  rotations_.assign(clusters_.size(), Eigen::Matrix3d::Identity());
}

void SkeletonForce::set_rest_shape(const Positions& rest) {
  compute_offsets(rest);
}

std::vector<int> SkeletonForce::cluster_sizes() const {
  std::vector<int> sizes;
  for (const auto& c : clusters_)
    sizes.push_back(static_cast<int>(c.members.size()));
  return sizes;
}

Eigen::Matrix3Xd SkeletonForce::node_positions(const Positions& x) const {
  Eigen::Matrix3Xd nodes(3, static_cast<Eigen::Index>(clusters_.size()));
  for (size_t k = 0; k < clusters_.size(); ++k) {
    const auto& c = clusters_[k];
    Eigen::Vector3d centre = Eigen::Vector3d::Zero();
    for (size_t m = 0; m < c.members.size(); ++m)
      centre += memberships_[c.entries[m]].weight * x.col(c.members[m]);
    nodes.col(k) =
        c.weight_sum > 0 ? Eigen::Vector3d(centre / c.weight_sum) : skeleton_.nodes_mm.col(k);
  }
  return nodes;
}

double SkeletonForce::add_forces(const State& state, Forces& f, bool want_energy) {
  const int n = state.size();
  if (n + 1 != static_cast<int>(first_.size()))
    throw std::invalid_argument("skeleton: the state has " + std::to_string(n) +
                                " particles, the skeleton was tied to " +
                                std::to_string(first_.size() - 1));
  const int clusters = static_cast<int>(clusters_.size());
  // Frames first (independent per cluster), then each particle's pulls gathered in cluster
  // order: the sums a scan of the clusters makes, for any thread count.
#pragma omp parallel for schedule(dynamic, 1) if (n >= kParallelMinParticles)
  for (int k = 0; k < clusters; ++k) {
    const auto& c = clusters_[k];
    if (c.members.empty()) continue;
    Eigen::Vector3d centre = Eigen::Vector3d::Zero();
    for (size_t m = 0; m < c.members.size(); ++m)
      centre += memberships_[c.entries[m]].weight * state.x.col(c.members[m]);
    centre /= c.weight_sum;
    Eigen::Matrix3d a = Eigen::Matrix3d::Zero();
    for (size_t m = 0; m < c.members.size(); ++m) {
      const Membership& ms = memberships_[c.entries[m]];
      a += ms.weight * (state.x.col(c.members[m]) - centre) * ms.offset.transpose();
    }
    centres_[k] = centre;
    rotations_[k] = closest_rotation(a);
  }
  const double ks = params_.stiffness;
  if (want_energy) energies_.assign(n, 0.0);
#pragma omp parallel for schedule(static) if (n >= kParallelMinParticles)
  for (int i = 0; i < n; ++i) {
    for (int e = first_[i]; e < first_[i + 1]; ++e) {
      const Membership& ms = memberships_[e];
      const int k = ms.cluster;
      const Eigen::Vector3d d = rotations_[k] * ms.offset + centres_[k] - state.x.col(i);
      f.col(i) += ks * ms.weight * d;
      if (want_energy) energies_[i] += 0.5 * ks * ms.weight * d.squaredNorm();
    }
  }
  double energy = 0;
  if (want_energy)
    for (double e : energies_)
      energy += e;  // in particle order, for any thread count
  return energy;
}

}  // namespace organfit::particles
