#include "organfit/fitting/attractive_points.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <numeric>
#include <stdexcept>
#include <string>

#include "organfit/geometry/sample_grid.h"
#include "organfit/particles/neighbour_list.h"

namespace organfit::fitting {

std::vector<int> first_shell_counts(const particles::Positions& x, double shell_mm,
                                    const std::vector<int>& of) {
  std::vector<int> w(static_cast<size_t>(x.cols()), 0);
  if (of.empty()) return w;
  const geometry::SampleGrid grid(x, shell_mm);
  const double shell2 = shell_mm * shell_mm;
  const long listed = static_cast<long>(of.size());
#pragma omp parallel if (listed >= particles::kParallelMinParticles)
  {
    std::vector<int> near;
#pragma omp for schedule(static)
    for (long a = 0; a < listed; ++a) {
      const int i = of[static_cast<size_t>(a)];
      near.clear();
      grid.within(x.col(i), shell_mm, near);  // a superset: within is <= the radius
      int count = 0;
      for (int j : near)
        count += j != i && (x.col(i) - x.col(j)).squaredNorm() < shell2;
      w[static_cast<size_t>(i)] = count;
    }
  }
  return w;
}

std::vector<int> first_shell_counts(const particles::Positions& x, double shell_mm) {
  std::vector<int> all(static_cast<size_t>(x.cols()));
  std::iota(all.begin(), all.end(), 0);
  return first_shell_counts(x, shell_mm, all);
}

void cap_by_cohesion(particles::Forces& g, const std::vector<int>& touched,
                     const std::vector<int>& w, double f_max) {
  for (int i : touched) {
    const double cap = 0.5 * std::max(1, w[i]) * f_max;
    const double mag = g.col(i).norm();
    if (mag > cap) g.col(i) *= cap / mag;
  }
}

std::pair<int, double> nearest_particle(const particles::Positions& x,
                                        const std::vector<int>& candidates,
                                        const Eigen::Vector3d& p_mm) {
  std::pair<int, double> best{-1, std::numeric_limits<double>::infinity()};
  for (int i : candidates) {
    const double d = (x.col(i) - p_mm).squaredNorm();
    if (d < best.second) best = {i, d};
  }
  return best;
}

std::pair<int, double> nearest_surface_particle(const particles::Positions& x,
                                                const std::vector<int>& candidates,
                                                const Eigen::Vector3d& p_mm,
                                                const SurfaceFeet& feet, double radius_mm) {
  std::pair<int, double> best{-1, std::numeric_limits<double>::infinity()};
  if (feet.empty()) {
    for (int i : candidates) {
      const double gap = (x.col(i) - p_mm).norm() - radius_mm;
      if (gap < best.second) best = {i, gap};
    }
    return best;
  }
  // The path from p to the particle through its foot: of particles stacked under one
  // foot, the outermost.
  double shortest = std::numeric_limits<double>::infinity();
  for (int i : candidates) {
    const double path =
        (x.col(i) + feet.offset_mm.col(i) - p_mm).norm() + feet.offset_mm.col(i).norm();
    if (path < shortest) shortest = path, best.first = i;
  }
  if (best.first >= 0) {
    const int i = best.first;
    best.second = feet.normal.col(i).dot(p_mm - x.col(i) - feet.offset_mm.col(i));
  }
  return best;
}

SkinIndex::SkinIndex(const particles::Positions& x, const std::vector<int>& candidates,
                     const SurfaceFeet* feet)
    : x_(x), candidates_(candidates), feet_(feet && !feet->empty() ? feet : nullptr) {
  const auto n = static_cast<Eigen::Index>(candidates.size());
  at_mm_.resize(3, n);
  for (Eigen::Index j = 0; j < n; ++j)
    at_mm_.col(j) = x.col(candidates[static_cast<size_t>(j)]);
  centres_ = std::make_unique<geometry::SampleGrid>(at_mm_);
  if (feet_) {
    foot_at_mm_.resize(3, n);
    for (Eigen::Index j = 0; j < n; ++j) {
      const int i = candidates[static_cast<size_t>(j)];
      foot_at_mm_.col(j) = x.col(i) + feet_->offset_mm.col(i);
    }
    feet_grid_ = std::make_unique<geometry::SampleGrid>(foot_at_mm_);
  }
}

SkinIndex::~SkinIndex() = default;

std::pair<int, double> SkinIndex::nearest_particle(const Eigen::Vector3d& p_mm) const {
  const auto [j, d2] = centres_->nearest(p_mm);
  return {j < 0 ? -1 : candidates_[static_cast<size_t>(j)], d2};
}

std::pair<int, double> SkinIndex::nearest_surface_particle(const Eigen::Vector3d& p_mm,
                                                           double radius_mm) const {
  if (!feet_) {
    // The least |p - x_i| - radius is the nearest centre's.
    const auto [i, d2] = nearest_particle(p_mm);
    if (i < 0) return {-1, std::numeric_limits<double>::infinity()};
    return {i, (x_.col(i) - p_mm).norm() - radius_mm};
  }
  // The path through a foot is no shorter than the distance to the foot.
  const auto [j, path] = feet_grid_->least(p_mm, [&](int k) {
    const int i = candidates_[static_cast<size_t>(k)];
    return (foot_at_mm_.col(k) - p_mm).norm() + feet_->offset_mm.col(i).norm();
  });
  if (j < 0) return {-1, std::numeric_limits<double>::infinity()};
  const int i = candidates_[static_cast<size_t>(j)];
  return {i, feet_->normal.col(i).dot(p_mm - x_.col(i) - feet_->offset_mm.col(i))};
}

void SkinIndex::within(const Eigen::Vector3d& centre_mm, double radius_mm,
                       std::vector<int>& out) const {
  out.clear();
  centres_->within(centre_mm, radius_mm, out);  // ascending position in candidates
  for (int& j : out)
    j = candidates_[static_cast<size_t>(j)];
}

double default_outlier_distance(const particles::Positions& x) {
  return x.cols() > 0 ? 0.5 * (x.rowwise().maxCoeff() - x.rowwise().minCoeff()).norm() : 0.0;
}

void validate_points(const std::vector<AttractivePoint>& points) {
  for (size_t k = 0; k < points.size(); ++k) {
    if (!points[k].p_mm.allFinite()) {
      throw std::invalid_argument("attractive point " + std::to_string(k) +
                                  " has a non-finite coordinate");
    }
    if (!(points[k].confidence > 0 && points[k].confidence <= 1)) {
      throw std::invalid_argument("attractive point " + std::to_string(k) +
                                  " has a confidence outside (0, 1]");
    }
  }
}

AttractivePointTerm::AttractivePointTerm(std::vector<AttractivePoint> points,
                                         const particles::LennardJones& law, double radius_mm,
                                         double skin_voxel_mm, double first_shell_r0)
    : points_(std::move(points)),
      rho_(radius_mm),
      r0_(law.r0()),
      f_max_(law.f_max()),
      skin_(skin_voxel_mm, radius_mm),
      first_shell_mm_(first_shell_r0 * law.r0()) {
  validate_points(points_);
  status_.resize(points_.size());
}

void AttractivePointTerm::count_first_shells(const particles::Positions& x) {
  w_ = first_shell_counts(x, first_shell_mm_, skin_.skin());
}

PaperAttractiveForce::PaperAttractiveForce(std::vector<AttractivePoint> points,
                                           const particles::LennardJones& law, double radius_mm,
                                           const PaperForceParams& params, double skin_voxel_mm)
    : AttractivePointTerm(std::move(points), law, radius_mm, skin_voxel_mm, params.first_shell_r0),
      params_(params) {
  if (!(params.alpha >= 1)) throw std::invalid_argument("attractive force: alpha must be >= 1");
  if (!(params.influence_radius_min_r0 > 0) ||
      !(params.influence_radius_max_r0 >= params.influence_radius_min_r0))
    throw std::invalid_argument("attractive force: need 0 < influence radius min <= max");
  if (!(params.influence_growth >= 0))
    throw std::invalid_argument("attractive force: influence growth must be >= 0");
  if (!(params.total_force_factor >= 1))
    throw std::invalid_argument("attractive force: total force factor must be >= 1");
  influence_.resize(points_.size());
  k_.assign(points_.size(), 0.0);
}

void PaperAttractiveForce::assign(const particles::Positions& x) {
  const auto& skin = skin_.skin();
  count_first_shells(x);
  // Default outlier distance: half the model's diameter.
  const double outlier =
      params_.outlier_distance_mm > 0 ? params_.outlier_distance_mm : default_outlier_distance(x);
  const SkinIndex index(x, skin);
  for (size_t k = 0; k < points_.size(); ++k) {
    PointStatus& st = status_[k];
    st = PointStatus{};
    influence_[k].clear();
    const Eigen::Vector3d& p = points_[k].p_mm;
    const auto [epicentre, d2] = index.nearest_particle(p);
    st.epicentre = epicentre;
    if (st.epicentre < 0) continue;
    st.d_min_mm = std::sqrt(d2);
    st.inside_model = skin_.inside(p);
    if (!st.inside_model && st.d_min_mm - rho_ > outlier) {
      st.rejected = true;
      continue;
    }
    if (st.d_min_mm <= rho_) {
      st.reached = true;
      continue;
    }
    const double radius = std::min(
        params_.influence_radius_max_r0 * r0_,
        params_.influence_radius_min_r0 * r0_ + params_.influence_growth * (st.d_min_mm - rho_));
    index.within(x.col(st.epicentre), radius, influence_[k]);
    st.influence_count = static_cast<int>(influence_[k].size());
    const int w = w_[st.epicentre];
    st.f_max_k = points_[k].confidence * 0.5 * w * f_max_;
    k_[k] = st.f_max_k / (st.d_min_mm - rho_);  // eq. 6
  }
}

double PaperAttractiveForce::add_forces(const particles::State& state, particles::Forces& f, bool) {
  if (skin_.update(state.x)) assign(state.x);
  g_.setZero(3, state.size());
  touched_.clear();
  for (size_t k = 0; k < points_.size(); ++k) {
    PointStatus& st = status_[k];
    if (st.rejected || influence_[k].empty()) continue;
    const Eigen::Vector3d& p = points_[k].p_mm;
    // d_min now: the smallest distance from the point over its influence set.
    double d_min = std::numeric_limits<double>::infinity();
    for (int i : influence_[k])
      d_min = std::min(d_min, (p - state.x.col(i)).norm());
    st.d_min_mm = d_min;
    st.reached = d_min <= rho_;
    if (st.reached) continue;
    // Forces of eq. 5; the epicentre's (ratio 1) is kept whole, the others are scaled
    // down together when the point's total would exceed its bound.
    double others = 0, epicentre_force = 0;
    thread_local std::vector<Eigen::Vector3d> g;
    g.assign(influence_[k].size(), Eigen::Vector3d::Zero());
    for (size_t m = 0; m < influence_[k].size(); ++m) {
      const int i = influence_[k][m];
      const Eigen::Vector3d to_p = p - state.x.col(i);
      const double r = to_p.norm();
      if (r <= rho_) continue;  // touching the point already
      const double ratio = std::min(1.0, (d_min - rho_) / (r - rho_));
      g[m] = k_[k] * std::pow(ratio, params_.alpha) * (r - rho_) * (to_p / r);  // eq. 5
      (i == st.epicentre ? epicentre_force : others) += g[m].norm();
    }
    const double room = params_.total_force_factor * st.f_max_k - epicentre_force;
    const double scale = others > room ? std::max(0.0, room) / others : 1.0;
    for (size_t m = 0; m < influence_[k].size(); ++m) {
      const int i = influence_[k][m];
      g_.col(i) += (i == st.epicentre ? 1.0 : scale) * g[m];
      touched_.push_back(i);
    }
  }
  std::sort(touched_.begin(), touched_.end());
  touched_.erase(std::unique(touched_.begin(), touched_.end()), touched_.end());
  cap_by_cohesion(g_, touched_, w_, f_max_);
  for (int i : touched_)
    f.col(i) += g_.col(i);
  return 0.0;
}

}  // namespace organfit::fitting
