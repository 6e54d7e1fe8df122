#include "organfit/fitting/spread_force.h"

#include <Eigen/Geometry>
#include <Eigen/QR>
#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>

#include "organfit/fitting/robust.h"
#include "organfit/particles/neighbour_list.h"

namespace organfit::fitting {

SpreadAttractiveForce::SpreadAttractiveForce(std::vector<AttractivePoint> points,
                                             const particles::LennardJones& law, double radius_mm,
                                             const SpreadForceParams& params, double skin_voxel_mm)
    : AttractivePointTerm(std::move(points), law, radius_mm, skin_voxel_mm, kFirstShellR0),
      kappa_(params.stiffness_fraction * law.stiffness()),
      params_(params) {
  if (!(params.stiffness_fraction > 0))
    throw std::invalid_argument("spread force: stiffness must be > 0");
  if (!(params.patch_sigma_r0 > 0) || !(params.patch_radius_r0 > 0))
    throw std::invalid_argument("spread force: patch sizes must be > 0");
  if (!(params.consistency_threshold >= 0) || params.consistency_neighbours < 0 ||
      !(params.consistency_noise_mm >= 0))
    throw std::invalid_argument("spread force: consistency test settings must be >= 0");
  patch_.resize(points_.size());
  if (params.consistency_threshold > 0) {
    std::vector<Eigen::Vector3d> p;
    for (const auto& a : points_)
      p.push_back(a.p_mm);
    neighbours_ = k_nearest(p, params.consistency_neighbours);
  }
}

void SpreadAttractiveForce::set_surface_feet(SurfaceFeet feet) {
  if (feet.normal.cols() != feet.offset_mm.cols() || !feet.offset_mm.allFinite() ||
      !feet.normal.allFinite() ||
      (feet.normal.cols() > 0 &&
       (feet.normal.colwise().norm().array() - 1.0).abs().maxCoeff() > 1e-6))
    throw std::invalid_argument(
        "spread force: surface feet must be finite, with one unit normal per offset");
  feet_ = std::move(feet);
  skin_.invalidate();  // re-assign the epicentres on the new surface
}

void SpreadAttractiveForce::assign(const particles::Positions& x) {
  const auto& skin = skin_.skin();
  count_first_shells(x);
  const double outlier =
      params_.outlier_distance_mm > 0 ? params_.outlier_distance_mm : default_outlier_distance(x);
  const double sigma = params_.patch_sigma_r0 * r0_, radius = params_.patch_radius_r0 * r0_;
  gap_.assign(points_.size(), 0.0);
  const SkinIndex index(x, skin, &feet_);
  const long points = static_cast<long>(points_.size());
#pragma omp parallel if (points >= 64)  // a nearest search and a patch each
  {
    std::vector<int> near;
#pragma omp for schedule(dynamic, 16)
    for (long k = 0; k < points; ++k) {  // each point's own status and patch
      PointStatus& st = status_[k];
      st = PointStatus{};
      patch_[k].clear();
      // Epicentre: the skin particle whose surface is nearest the point.
      const auto [epicentre, gap] = index.nearest_surface_particle(points_[k].p_mm, rho_);
      st.epicentre = epicentre;
      if (st.epicentre < 0) continue;
      gap_[k] = gap;
      st.d_min_mm = (x.col(st.epicentre) - points_[k].p_mm).norm();
      st.inside_model = skin_.inside(points_[k].p_mm);
      if (!st.inside_model && gap > outlier) {
        st.rejected = true;
        continue;
      }
      const Eigen::Vector3d e = x.col(st.epicentre);
      index.within(e, radius, near);
      for (int i : near) {
        const double d2 = (x.col(i) - e).squaredNorm();
        patch_[k].push_back({i, points_[k].confidence * std::exp(-d2 / (2 * sigma * sigma))});
      }
      st.influence_count = static_cast<int>(patch_[k].size());
    }
  }
  // Points far off the surface compared with the others (median + 5 x 1.4826 MAD, and
  // more than 2 r0) are not boundary data: e.g. a point deep inside the organ.
  std::vector<double> off;
  for (size_t k = 0; k < status_.size(); ++k)
    if (!status_[k].rejected && status_[k].epicentre >= 0) off.push_back(std::abs(gap_[k]));
  if (off.size() >= 5) {
    const double cut = std::max(2.0 * r0_, outlier_cutoff(off, 5.0));
    for (size_t k = 0; k < status_.size(); ++k) {
      PointStatus& st = status_[k];
      if (!st.rejected && st.epicentre >= 0 && std::abs(gap_[k]) > cut) {
        st.rejected = true;
        patch_[k].clear();
      }
    }
  }
  // A lone jump among neighbours: signed residuals (inside the model: negative).
  if (!neighbours_.empty()) {
    std::vector<double> residual(points_.size(), 0.0);
    std::vector<char> use(points_.size(), 0);
    for (size_t k = 0; k < status_.size(); ++k) {
      const PointStatus& st = status_[k];
      if (st.rejected || st.epicentre < 0) continue;
      // The tangent plane's gap is signed; the balls' is not below a dent (inside: negative).
      residual[k] = !feet_.empty() ? gap_[k] : st.inside_model ? -std::abs(gap_[k]) : gap_[k];
      use[k] = 1;
    }
    const double epsilon =
        params_.consistency_noise_mm > 0 ? params_.consistency_noise_mm : 0.5 * rho_;
    const std::vector<char> lone =
        normalised_median_test(residual, neighbours_, use, params_.consistency_threshold, epsilon);
    for (size_t k = 0; k < status_.size(); ++k)
      if (lone[k]) status_[k].rejected = true, patch_[k].clear();
  }
  in_patches_.clear();
  for (const auto& patch : patch_)
    for (const auto& [i, w] : patch)
      in_patches_.push_back(i);
  std::sort(in_patches_.begin(), in_patches_.end());
  in_patches_.erase(std::unique(in_patches_.begin(), in_patches_.end()), in_patches_.end());
  // The same pairs by particle: counted, then listed point by point (points ascending).
  std::vector<int> slot(static_cast<size_t>(x.cols()), -1);  // particle -> its j
  const size_t m = in_patches_.size();
  for (size_t j = 0; j < m; ++j)
    slot[in_patches_[j]] = static_cast<int>(j);
  pull_first_.assign(m + 1, 0);
  for (const auto& patch : patch_)
    for (const auto& [i, w] : patch)
      ++pull_first_[slot[i] + 1];
  for (size_t j = 0; j < m; ++j)
    pull_first_[j + 1] += pull_first_[j];
  pulls_.resize(pull_first_[m]);
  std::vector<int> fill(pull_first_.begin(), pull_first_.end() - 1);
  for (size_t k = 0; k < patch_.size(); ++k)
    for (const auto& [i, w] : patch_[k])
      pulls_[fill[slot[i]]++] = {static_cast<int>(k), w};
}

double SpreadAttractiveForce::add_forces(const particles::State& state, particles::Forces& f,
                                         bool) {
  if (skin_.update(state.x)) assign(state.x);
  // Each point's residual r_k (independent of the others).
  const long points = static_cast<long>(points_.size());
  residual_.resize(points_.size());
  pulls_now_.assign(points_.size(), 0);
#pragma omp parallel for schedule(static) if (points >= particles::kParallelMinParticles)
  for (long k = 0; k < points; ++k) {
    PointStatus& st = status_[k];
    if (st.rejected || patch_[k].empty()) continue;
    const int e = st.epicentre;
    const Eigen::Vector3d to_p = points_[k].p_mm - state.x.col(e);
    const double d = to_p.norm();
    st.d_min_mm = d;
    if (!feet_.empty()) {
      const Eigen::Vector3d normal = feet_.normal.col(e);
      const double gap = normal.dot(to_p - feet_.offset_mm.col(e));
      st.reached = std::abs(gap) < 1e-3 * rho_;
      residual_[k] = gap * normal;
    } else {
      st.reached = std::abs(d - rho_) < 1e-3 * rho_;
      if (d < 1e-12) continue;
      residual_[k] = (d - rho_) * (to_p / d);
    }
    pulls_now_[k] = 1;
  }
  // Each patch particle's force: its pulls, normalised and capped. Pressure compensation:
  // the patches' net outward push, sum F_i . n_i, is taken back evenly over the whole
  // skin, so the local stage moves the surface without inflating or deflating the body
  // (normals radial from the centroid: organs are near-convex).
  const auto& skin = skin_.skin();
  const Eigen::Vector3d centroid = state.x.rowwise().mean();
  const long m = static_cast<long>(in_patches_.size());
  pull_.assign(in_patches_.size(), Eigen::Vector3d::Zero());
#pragma omp parallel for schedule(static) if (m >= particles::kParallelMinParticles)
  for (long j = 0; j < m; ++j) {
    Eigen::Vector3d num = Eigen::Vector3d::Zero();
    double den = 0;
    for (int e = pull_first_[j]; e < pull_first_[j + 1]; ++e) {
      const auto [k, w] = pulls_[e];
      if (!pulls_now_[k]) continue;
      num += w * residual_[k];
      den += w;
    }
    if (den == 0) continue;
    const int i = in_patches_[j];
    Eigen::Vector3d force = kappa_ * num / std::max(1.0, den);
    const double mag = force.norm(), cap = 0.5 * std::max(1, w_[i]) * f_max_;  // W(i) F_max / 2
    if (mag > cap) force *= cap / mag;
    f.col(i) += force;
    pull_[j] = force;
  }
  double inflation = 0;  // the pulls' outward parts, in particle order for any thread count
  for (size_t j = 0; j < pull_.size(); ++j)
    inflation += pull_[j].dot((state.x.col(in_patches_[j]) - centroid).normalized());
  const double pressure =
      !skin.empty() && params_.hold_volume ? inflation / static_cast<double>(skin.size()) : 0.0;
  if (pressure != 0) {
    const long skin_count = static_cast<long>(skin.size());
#pragma omp parallel for schedule(static) if (skin_count >= particles::kParallelMinParticles)
    for (long s = 0; s < skin_count; ++s) {
      const int i = skin[s];
      f.col(i) -= pressure * (state.x.col(i) - centroid).normalized();
    }
  }
  if (params_.hold_pose) hold_pose(state, centroid, pressure, f);
  return 0.0;
}

void SpreadAttractiveForce::hold_pose(const particles::State& state,
                                      const Eigen::Vector3d& centroid, double pressure,
                                      particles::Forces& f) const {
  // The term's net force and torque about the centroid, summed in particle order (the
  // same for any thread count): the pulls, then the pressure's share on the skin.
  Eigen::Vector3d net = Eigen::Vector3d::Zero(), torque = Eigen::Vector3d::Zero();
  for (size_t j = 0; j < in_patches_.size(); ++j) {
    net += pull_[j];
    torque += (state.x.col(in_patches_[j]) - centroid).cross(pull_[j]);
  }
  if (pressure != 0)
    for (const int i : skin_.skin()) {
      const Eigen::Vector3d r = state.x.col(i) - centroid;
      const Eigen::Vector3d push = -pressure * r.normalized();
      net += push;
      torque += r.cross(push);
    }
  if (net.isZero() && torque.isZero()) return;
  // The body's second moment about its centroid (per unit mass: the particles weigh the
  // same), in blocks of fixed size summed in order, then the rigid motion's forces taken
  // back: the same net force and torque, spread as a rigid body's accelerations are.
  const long n = state.size();
  constexpr long kBlock = 4096;
  const long blocks = (n + kBlock - 1) / kBlock;
  std::vector<Eigen::Matrix3d> part(static_cast<size_t>(blocks), Eigen::Matrix3d::Zero());
#pragma omp parallel for schedule(static) if (n >= particles::kParallelMinParticles)
  for (long b = 0; b < blocks; ++b) {
    Eigen::Matrix3d sum = Eigen::Matrix3d::Zero();
    for (long i = b * kBlock; i < std::min(n, (b + 1) * kBlock); ++i) {
      const Eigen::Vector3d r = state.x.col(i) - centroid;
      sum.noalias() += r.squaredNorm() * Eigen::Matrix3d::Identity() - r * r.transpose();
    }
    part[static_cast<size_t>(b)] = sum;
  }
  Eigen::Matrix3d inertia = Eigen::Matrix3d::Zero();
  for (const auto& p : part)
    inertia += p;
  // A body of fewer than 3 particles, or all on a line, has no turn about that line: the
  // pseudo-inverse leaves it.
  const Eigen::Vector3d alpha = inertia.completeOrthogonalDecomposition().pseudoInverse() * torque;
  const Eigen::Vector3d per_particle = net / static_cast<double>(n);
#pragma omp parallel for schedule(static) if (n >= particles::kParallelMinParticles)
  for (long i = 0; i < n; ++i)
    f.col(i) -= per_particle + alpha.cross(state.x.col(i) - centroid);
}

}  // namespace organfit::fitting
