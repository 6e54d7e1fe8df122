#include "organfit/particles/skeleton.h"

#include <Eigen/LU>
#include <Eigen/SVD>
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <set>
#include <stdexcept>
#include <string>

#include "organfit/geometry/image_geometry.h"
#include "organfit/geometry/mask_ops.h"
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

/// The medial nodes of a body given as n sample points (particles or voxel centres) at
/// `position(i)`, each with its depth (mm) and feature (the sample of its nearest surface
/// point, -1 when the body has no surface): `for_each_pair(visit)` calls visit(i, j) for
/// pairs of close neighbours (possibly on threads, a pair possibly twice), `min_lambda_mm`
/// is the sampling's own scale (see below).
template <class Position, class ForEachPair>
Skeleton medial_nodes(int n, Position&& position, const std::vector<double>& depth,
                      const std::vector<int>& feature, ForEachPair&& for_each_pair,
                      double min_lambda_mm, double node_spacing_mm) {
  Skeleton skeleton;
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
        (position(feature[i]) - position(feature[j])).norm() >= 2 * lambda) {
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
  Eigen::Matrix3Xd at(3, static_cast<Eigen::Index>(candidates.size()));
  for (size_t c = 0; c < candidates.size(); ++c)
    at.col(static_cast<Eigen::Index>(c)) = position(candidates[c]);
  size_t start = 0;
  for (size_t c = 0; c < candidates.size(); ++c)
    if (depth[candidates[c]] > depth[candidates[start]]) start = c;
  std::vector<size_t> chosen = {start};
  std::vector<double> gap(candidates.size(), std::numeric_limits<double>::infinity());
  for (;;) {
    int best = -1;
    double best_gap = node_spacing_mm;
    for (size_t c = 0; c < candidates.size(); ++c) {
      const auto e = static_cast<Eigen::Index>(c);
      gap[c] =
          std::min(gap[c], (at.col(e) - at.col(static_cast<Eigen::Index>(chosen.back()))).norm());
      if (gap[c] >= best_gap) best_gap = gap[c], best = static_cast<int>(c);
    }
    if (best < 0) break;
    chosen.push_back(static_cast<size_t>(best));
  }
  skeleton.nodes_mm.resize(3, static_cast<Eigen::Index>(chosen.size()));
  for (size_t k = 0; k < chosen.size(); ++k)
    skeleton.nodes_mm.col(static_cast<Eigen::Index>(k)) =
        at.col(static_cast<Eigen::Index>(chosen[k]));
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
  // Depth and feature: the Euclidean distance to, and index of, the nearest surface
  // particle (exact, by a grid search over them; a graph distance through the lattice is
  // anisotropic and frays the medial axis), searched by boxes of 2 a (a speed setting only).
  std::vector<int> on_surface;
  for (int i = 0; i < n; ++i)
    if (surface[i]) on_surface.push_back(i);
  std::vector<double> depth(n, 0.0);
  std::vector<int> feature(n, -1);
  if (!on_surface.empty()) {
    Eigen::Matrix3Xd at(3, static_cast<Eigen::Index>(on_surface.size()));
    for (size_t k = 0; k < on_surface.size(); ++k)
      at.col(static_cast<Eigen::Index>(k)) = rest.col(on_surface[k]);
    const std::vector<std::pair<int, double>> found =
        geometry::SampleGrid(at).nearest_each(rest, 2.0 * a_nn_mm);
#pragma omp parallel for schedule(static) if (n >= kParallelMinParticles)
    for (int i = 0; i < n; ++i) {
      const auto [k, d2] = found[static_cast<size_t>(i)];
      depth[i] = std::sqrt(d2);
      feature[i] = on_surface[static_cast<size_t>(k)];
    }
  }
  // Neighbours may pick features up to a + 1.2 a + a apart: lambda >= 2 a.
  return medial_nodes(
      n, [&rest](int i) -> Eigen::Vector3d { return rest.col(i); }, depth, feature, for_each_pair,
      2.0 * a_nn_mm, node_spacing_mm);
}

Skeleton medial_skeleton(const geometry::LabelVolume& mask, double node_spacing_mm) {
  if (!(node_spacing_mm > 0)) throw std::invalid_argument("skeleton: node spacing must be > 0 mm");
  const auto& g = mask.geometry;
  // The inside voxels' box grown by a voxel (within the grid): every surface voxel's
  // outside neighbour is in it or off the grid.
  int lo[3] = {g.size[0], g.size[1], g.size[2]}, hi[3] = {-1, -1, -1};
  const long long sx = g.size[0], sxy = sx * g.size[1];
  for (long long v = 0; v < g.voxel_count(); ++v)
    if (mask.labels[static_cast<size_t>(v)]) {
      const int idx[3] = {static_cast<int>(v % sx), static_cast<int>((v / sx) % g.size[1]),
                          static_cast<int>(v / sxy)};
      for (int d = 0; d < 3; ++d)
        lo[d] = std::min(lo[d], idx[d]), hi[d] = std::max(hi[d], idx[d]);
    }
  if (hi[0] < 0) throw std::invalid_argument("skeleton: the mask is empty");
  geometry::ImageGeometry box = g;
  for (int d = 0; d < 3; ++d) {
    lo[d] = std::max(0, lo[d] - 1), hi[d] = std::min(g.size[d] - 1, hi[d] + 1);
    box.size[d] = hi[d] - lo[d] + 1;
  }
  box.origin_mm = g.index_to_physical(Eigen::Vector3d(lo[0], lo[1], lo[2]));
  const long long bx = box.size[0], bxy = bx * box.size[1];
  const long long box_voxels = box.voxel_count();
  std::vector<std::uint8_t> inside(static_cast<size_t>(box_voxels)), surface(inside.size(), 0);
  for (int k = 0; k < box.size[2]; ++k)
    for (int j = 0; j < box.size[1]; ++j)
      for (int i = 0; i < box.size[0]; ++i)
        inside[static_cast<size_t>(k * bxy + j * bx + i)] =
            mask.at(lo[0] + i, lo[1] + j, lo[2] + k) ? 1 : 0;
  // The voxel centres stand for the particles, in index order: sample a is box voxel
  // voxel[a]; its place is the mask grid's own (the same numbers as the grid gives).
  std::vector<int> voxel;
  std::vector<int> sample_of(inside.size(), -1);
  const long long stride[3] = {1, bx, bxy};
  for (long long v = 0; v < box_voxels; ++v) {
    if (!inside[static_cast<size_t>(v)]) continue;
    const int idx[3] = {static_cast<int>(v % bx), static_cast<int>((v / bx) % box.size[1]),
                        static_cast<int>(v / bxy)};
    sample_of[static_cast<size_t>(v)] = static_cast<int>(voxel.size());
    voxel.push_back(static_cast<int>(v));
    // The surface: a face neighbour outside (or off the grid).
    for (int d = 0; d < 3 && !surface[static_cast<size_t>(v)]; ++d)
      for (int s = -1; s <= 1; s += 2) {
        const int at = idx[d] + s;
        if (at < 0 || at >= box.size[d] || !inside[static_cast<size_t>(v + s * stride[d])])
          surface[static_cast<size_t>(v)] = 1;
      }
  }
  const int n = static_cast<int>(voxel.size());
  auto position = [&](int a) -> Eigen::Vector3d {
    const long long v = voxel[static_cast<size_t>(a)];
    return g.index_to_physical(Eigen::Vector3d(static_cast<double>(lo[0] + v % bx),
                                               static_cast<double>(lo[1] + (v / bx) % box.size[1]),
                                               static_cast<double>(lo[2] + v / bxy)));
  };
  // Depth and feature: the Euclidean distance to, and the nearest, surface voxel, exact by
  // the distance transform's passes (linear in the voxels; a search per voxel among the
  // surface's took 23 s for a 2.5 L organ on 0.8 x 0.8 x 0.5 mm voxels).
  const std::vector<int> nearest = geometry::nearest_feature_transform(surface, box);
  std::vector<double> depth(n, 0.0);
  std::vector<int> feature(n, -1);
#pragma omp parallel for schedule(static)
  for (int a = 0; a < n; ++a) {
    const int f = nearest[static_cast<size_t>(voxel[static_cast<size_t>(a)])];
    feature[a] = sample_of[static_cast<size_t>(f)];
    depth[a] = std::sqrt((position(feature[a]) - position(a)).squaredNorm());
  }
  // Neighbours: face neighbours both inside, each pair once.
  auto for_each_pair = [&](auto&& visit) {
#pragma omp parallel for schedule(static)
    for (int a = 0; a < n; ++a) {
      const long long v = voxel[static_cast<size_t>(a)];
      const int idx[3] = {static_cast<int>(v % bx), static_cast<int>((v / bx) % box.size[1]),
                          static_cast<int>(v / bxy)};
      for (int d = 0; d < 3; ++d)
        if (idx[d] + 1 < box.size[d] && inside[static_cast<size_t>(v + stride[d])])
          visit(a, sample_of[static_cast<size_t>(v + stride[d])]);
    }
  };
  return medial_nodes(n, position, depth, feature, for_each_pair, 2.0 * g.spacing_mm.maxCoeff(),
                      node_spacing_mm);
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
