#include "global_solvers.h"

#include <omp.h>

#include <Eigen/Dense>
#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstdint>
#include <limits>
#include <numeric>
#include <optional>
#include <vector>

#include "organfit/fitting/robust.h"
#include "organfit/geometry/morton.h"
#include "organfit/geometry/sample_grid.h"

namespace organfit::fitting {
namespace {

/// The affine part's volume constraint det(a) = 1 linearised at the current a (det 1):
/// det(a + da) = 1 + tr(a^-1 da) + O(da^2), so tr(a^-1 da) = 0, i.e. g . d theta = 0 with
/// g_(3i+j) = (a^-1)_ji on theta's first nine entries (a, row-major) and 0 on the rest (n).
Eigen::VectorXd unit_determinant_normal(const Eigen::Matrix3d& a, Eigen::Index n) {
  Eigen::VectorXd g = Eigen::VectorXd::Zero(n);
  const Eigen::Matrix3d b = a.inverse();
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j)
      g(3 * i + j) = b(j, i);
  return g;
}

/// argmin_x 1/2 x^T h x - b^T x subject to g . x = c (h symmetric positive definite): the
/// normal equations with one linear constraint, solved by its Lagrange multiplier. Why:
/// a fit solved without the volume constraint and rescaled to det 1 afterwards is not the
/// best volume-preserving fit: two points 8 mm beyond a 30 mm cube's faces asked for a
/// stretch of 1.53, the unconstrained fit gave it along x with y and z unchanged, and
/// the rescaling took it back to 1.53^(2/3) = 1.33, every time.
Eigen::VectorXd solve_on_constraint(const Eigen::MatrixXd& h, const Eigen::VectorXd& b,
                                    const Eigen::VectorXd& g, double c) {
  const Eigen::LDLT<Eigen::MatrixXd> ldlt = h.ldlt();
  const Eigen::VectorXd x = ldlt.solve(b), hg = ldlt.solve(g);
  const double ghg = g.dot(hg);
  if (!(ghg > 0)) return x;
  return x - ((g.dot(x) - c) / ghg) * hg;
}

/// Stiffness annealing (as in non-rigid ICP, Amberg et al. 2007): the pull towards no
/// change starts 10^(levels - 1) times the stated one and is relaxed tenfold each time
/// the fit settles, or after `iterations` steps at a level. Closest-point matches made
/// from the identity are poor for a large change of shape; a stiff first fit gets them
/// close.
struct StiffnessSchedule {
  int levels, iterations;
  int level = 0, steps = 0;  ///< the current level, and the steps taken at it
  double factor() const { return std::pow(10.0, levels - 1 - level); }
  /// Moves to the next level when the fit `settled` or the level's steps are used up;
  /// false when that was the last level (stop).
  bool go_on(bool settled) {
    if (!settled && steps < iterations) return true;
    if (level == levels - 1) return false;
    ++level, steps = 0;
    return true;
  }
};

/// The closest-point step of the map x -> a s + t + B(s) c (a row-major, then t, then
/// the K shear coefficients c; B(s) the shears' 3 x K Jacobian at sample s): the weighted
/// normal equations of point-to-plane rows n^T (a s + t + B c) = n^T p, with n the
/// matched normal mapped by a^-T, and point-to-point rows (.)_r = p_r weighted
/// `point_to_point`; pulls lambda_a |a - I|^2 and lambda_c |c|^2. Returns their
/// solution theta (12 + K). `match[k]` is point k's sample, `w[k]` its weight (0: unused).
template <int K, class ShearJacobian>
Eigen::Matrix<double, 12 + K, 1> solve_matched_step(
    const SurfaceSamples& surface, const Eigen::Matrix3Xd& p, const std::vector<int>& match,
    const std::vector<double>& w, const Eigen::Matrix3d& normal_map, double point_to_point,
    double lambda_a, double lambda_c, ShearJacobian&& jacobian) {
  using Vec = Eigen::Matrix<double, 12 + K, 1>;
  Eigen::Matrix<double, 12 + K, 12 + K> nrm = Eigen::Matrix<double, 12 + K, 12 + K>::Zero();
  Vec rhs = Vec::Zero();
  for (Eigen::Index k = 0; k < p.cols(); ++k) {
    if (w[k] == 0) continue;
    const Eigen::Vector3d s = surface.points.col(match[k]);
    const Eigen::Vector3d n = (normal_map * surface.normals.col(match[k])).normalized();
    const Eigen::Matrix<double, 3, K> b = jacobian(match[k]);
    Vec row;
    row.template segment<3>(0) = n.x() * s, row.template segment<3>(3) = n.y() * s;
    row.template segment<3>(6) = n.z() * s, row.template segment<3>(9) = n;
    if constexpr (K > 0) row.template tail<K>() = (n.transpose() * b).transpose();
    nrm += w[k] * row * row.transpose();
    rhs += w[k] * row * n.dot(p.col(k));
    for (int c = 0; c < 3; ++c) {
      Vec pp = Vec::Zero();
      pp.template segment<3>(3 * c) = s;
      pp(9 + c) = 1.0;
      if constexpr (K > 0) pp.template tail<K>() = b.row(c).transpose();
      nrm += point_to_point * w[k] * pp * pp.transpose();
      rhs += point_to_point * w[k] * pp * p(c, k);
    }
  }
  for (int c = 0; c < 3; ++c) {
    for (int d = 0; d < 3; ++d)
      nrm(3 * c + d, 3 * c + d) += lambda_a;
    rhs(3 * c + c) += lambda_a;
  }
  for (int c = 0; c < K; ++c)
    nrm(12 + c, 12 + c) += lambda_c;
  return nrm.ldlt().solve(rhs);
}

}  // namespace

namespace detail {

double robust_weights(const std::vector<double>& r, const std::vector<AttractivePoint>& points,
                      double mads, std::vector<double>& w) {
  const double cut = outlier_cutoff(r, mads);
  double sum = 0;
  int kept = 0;
  w.assign(r.size(), 0.0);
  for (size_t k = 0; k < r.size(); ++k) {
    w[k] = r[k] <= cut ? points[k].confidence : 0.0;
    if (w[k] > 0) sum += r[k] * r[k], ++kept;
  }
  return std::sqrt(sum / std::max(1, kept));
}

double nearest_sample_rms(const MappedSamples& mapped, const std::vector<AttractivePoint>& points,
                          double mads) {
  const geometry::SampleGrid grid(mapped.full, geometry::SampleGrid::surface_cell_mm(mapped.full));
  std::vector<double> r(points.size()), w;
  const auto m = static_cast<long long>(points.size());
#pragma omp parallel for schedule(static)
  for (long long k = 0; k < m; ++k)
    r[static_cast<size_t>(k)] = std::sqrt(grid.nearest(points[static_cast<size_t>(k)].p_mm).second);
  return robust_weights(r, points, mads, w);
}

double nearest_sample_rms(const GlobalMap& map, const SurfaceSamples& surface,
                          const std::vector<AttractivePoint>& points, double mads) {
  return nearest_sample_rms(map_samples(map, surface), points, mads);
}

MappedSampleSearch::MappedSampleSearch(const Eigen::Matrix3Xd& samples)
    : samples_(samples),
      grid_(std::make_unique<geometry::SampleGrid>(
          samples, geometry::SampleGrid::surface_cell_mm(samples))) {}

MappedSampleSearch::~MappedSampleSearch() = default;

void MappedSampleSearch::nearest(const GlobalMap& map, const Eigen::Matrix3Xd& p,
                                 std::vector<int>& match, std::vector<double>& r) const {
  const Eigen::Index m = p.cols();
  match.assign(static_cast<size_t>(m), -1);
  r.assign(static_cast<size_t>(m), std::numeric_limits<double>::infinity());
  if (m == 0 || samples_.cols() == 0) return;
  GlobalMap f;  // the affine part and the quadratic shears alone (f.apply: no fields, no flow)
  f.affine = map.affine;
  f.shears = map.shears;
  const Eigen::Matrix3d a_inverse = f.affine.a.inverse();
  Eigen::Matrix3Xd q(3, m);
  std::vector<double> reach(static_cast<size_t>(m));  // D + e, each point
#pragma omp parallel for schedule(static)
  for (Eigen::Index k = 0; k < m; ++k) {
    q.col(k) = f.inverse(p.col(k), a_inverse);
    if (!q.col(k).allFinite()) continue;  // no pre-image: every sample moved, below
    const double e = (f.apply(q.col(k)) - p.col(k)).norm();
    const int near = grid_->nearest(q.col(k)).first;
    reach[static_cast<size_t>(k)] = (f.apply(samples_.col(near)) - p.col(k)).norm() + e;
  }
  // Every sample moved, and a grid over them: where there is no bound, and where the
  // points' searches would examine more samples than that moves (10,000 points on a
  // million particles' surface). The same images and ties either way: the same answers.
  auto move_all = [&] {
    Eigen::Matrix3Xd moved(3, samples_.cols());
#pragma omp parallel for schedule(static)
    for (Eigen::Index j = 0; j < samples_.cols(); ++j)
      moved.col(j) = f.apply(samples_.col(j));
    const geometry::SampleGrid grid(moved, geometry::SampleGrid::surface_cell_mm(moved));
#pragma omp parallel for schedule(static)
    for (Eigen::Index k = 0; k < m; ++k) {
      const auto [j, d2] = grid.nearest(p.col(k));
      match[static_cast<size_t>(k)] = j, r[static_cast<size_t>(k)] = std::sqrt(d2);
    }
  };
  if (!q.allFinite()) return move_all();
  std::atomic<long long> examined{0};
  const long long budget = samples_.cols();
#pragma omp parallel
  {
    std::vector<int> around;
#pragma omp for schedule(dynamic, 1)
    for (Eigen::Index k = 0; k < m; ++k) {
      if (examined.load(std::memory_order_relaxed) > budget) continue;  // moved all below
      // The bound over the box about p holding f(q) and every image within D of p (one
      // far point's box would loosen every other's bound), widened by a relative 1e-9 for
      // the rounding of the images.
      const double reach_k = reach[static_cast<size_t>(k)];
      const StretchBound bound =
          f.inverse_stretch({p.col(k).array() - reach_k, p.col(k).array() + reach_k});
      const double radius = (bound.stretch * reach_k + 2 * bound.slack_mm) * (1 + 1e-9) + 1e-9;
      if (!std::isfinite(radius)) {
        examined.store(budget + 1);
        continue;
      }
      around.clear();
      grid_->within(q.col(k), radius, around);  // ascending index: ties go to the first
      examined.fetch_add(static_cast<long long>(around.size()) + 1, std::memory_order_relaxed);
      int best = -1;
      double best_d2 = std::numeric_limits<double>::infinity();
      for (const int j : around) {
        const double d2 = (f.apply(samples_.col(j)) - p.col(k)).squaredNorm();
        if (d2 < best_d2) best = j, best_d2 = d2;
      }
      match[static_cast<size_t>(k)] = best, r[static_cast<size_t>(k)] = std::sqrt(best_d2);
    }
  }
  if (examined.load() > budget) move_all();
}

MappedDistance mapped_distance(const GlobalMap& map, const Eigen::Matrix3d& b,
                               const geometry::SignedDistance& distance, const Eigen::Vector3d& p) {
  MappedDistance out;
  out.q = map.inverse(p, b);
  Eigen::Vector3d grad;
  const double d = distance.at(out.q, &grad);
  out.gp = b.transpose() * grad;
  out.nu = std::max(out.gp.norm(), 0.1);
  out.r = d / out.nu;
  return out;
}

}  // namespace detail

using detail::mapped_distance;
using detail::MappedDistance;
using detail::MappedSampleSearch;
using detail::nearest_sample_rms;
using detail::robust_weights;

AffineFit fit_volume_preserving_affine(const SurfaceSamples& surface,
                                       const std::vector<AttractivePoint>& points,
                                       const AffineFitOptions& o) {
  AffineFit fit;
  const int m = static_cast<int>(points.size());
  // Even one or two points are well posed: the pull towards the identity picks the
  // least change that reaches them (two points: a stretch along their axis).
  if (m < 1 || surface.points.cols() == 0) return fit;
  Eigen::Matrix3Xd p(3, m);
  for (int k = 0; k < m; ++k)
    p.col(k) = points[k].p_mm;
  const Eigen::Vector3d sc = surface.points.rowwise().mean();
  const double spread2 = (surface.points.colwise() - sc).squaredNorm() / surface.points.cols();
  const double lambda_final = o.regularisation * spread2 * m;

  std::vector<int> match(m);
  std::vector<double> r(m), w(m);
  const MappedSampleSearch search(surface.points);
  auto correspond = [&](const Eigen::Matrix3d& a, const Eigen::Vector3d& t) {
    GlobalMap affine;
    affine.affine.a = a, affine.affine.t = t;
    search.nearest(affine, p, match, r);
    return robust_weights(r, points, o.outlier_mads, w);
  };
  fit.rms_before_mm = correspond(fit.a, fit.t);
  double previous = fit.rms_before_mm;
  // The pull starts 1000x the stated one, where the fit is nearly a translation.
  StiffnessSchedule schedule{4, o.iterations};
  for (int it = 0; it < schedule.levels * o.iterations; ++it) {
    const double lambda = lambda_final * schedule.factor();
    const Eigen::Matrix<double, 12, 1> theta =
        solve_matched_step<0>(surface, p, match, w, fit.a.inverse().transpose(), o.point_to_point,
                              lambda, 0.0, [](int) { return Eigen::Matrix<double, 3, 0>(); });
    Eigen::Matrix3d a;
    a << theta.segment<3>(0).transpose(), theta.segment<3>(3).transpose(),
        theta.segment<3>(6).transpose();
    Eigen::Vector3d t = theta.segment<3>(9);
    const double det = a.determinant();
    if (!(det > 0) || !a.allFinite() || !t.allFinite())
      break;  // degenerate: keep the last good map
    // det(a) = 1, scaling about the matched surface's centroid so the fit stays in place.
    const double scale = 1.0 / std::cbrt(det);
    Eigen::Vector3d centroid = Eigen::Vector3d::Zero();
    double wsum = 0;
    for (int k = 0; k < m; ++k)
      centroid += w[k] * surface.points.col(match[k]), wsum += w[k];
    centroid /= std::max(wsum, 1e-12);
    const Eigen::Vector3d image = a * centroid + t;
    a *= scale;
    t = image - a * centroid;
    const double rms = correspond(a, t);
    fit.a = a;
    fit.t = t;
    fit.iterations = it + 1;
    fit.rms_after_mm = rms;
    const bool settled = std::abs(previous - rms) < 1e-5 * (1 + previous);
    previous = rms;
    ++schedule.steps;
    if (!schedule.go_on(settled)) break;
  }
  if (fit.iterations == 0) fit.rms_after_mm = fit.rms_before_mm;
  return fit;
}

namespace {

/// Geman-McClure loss of scale sqrt(c2) (mm): sum_k conf_k c2 r_k^2 / (c2 + r_k^2), and the
/// weights of its iteratively reweighted least squares, conf_k (c2 / (c2 + r_k^2))^2.
double geman_mcclure(const std::vector<AttractivePoint>& points, const Eigen::VectorXd& r,
                     double c2) {
  double e = 0;
  for (Eigen::Index k = 0; k < r.size(); ++k)
    e += points[k].confidence * c2 * r(k) * r(k) / (c2 + r(k) * r(k));
  return e;
}
Eigen::VectorXd geman_mcclure_weights(const std::vector<AttractivePoint>& points,
                                      const Eigen::VectorXd& r, double c2) {
  Eigen::VectorXd w(r.size());
  for (Eigen::Index k = 0; k < r.size(); ++k) {
    const double f = c2 / (c2 + r(k) * r(k));
    w(k) = points[k].confidence * f * f;
  }
  return w;
}

/// Robust Gauss-Newton with a backtracking line search, the loop of both fits on the
/// signed distance: `step_of(map, w)` is the step for the current residuals r, their
/// Jacobian jac and Geman-McClure weights w (scale c2); `trial(map, step, alpha)` the map
/// moved by alpha x step (nullopt: not a map); `residuals(g, r, jac or nullptr)` and
/// `objective(g, r)` measure a map. Steps until `iterations`, until no step lowers the
/// objective, or until it settles (a relative fall below 1e-6); r and jac are left the
/// final map's. Returns the steps taken.
template <class StepOf, class Trial, class Residuals, class Objective>
int robust_gauss_newton(GlobalMap& map, Eigen::VectorXd& r, Eigen::MatrixXd& jac,
                        const std::vector<AttractivePoint>& points, double c2, int iterations,
                        StepOf&& step_of, Trial&& trial, Residuals&& residuals,
                        Objective&& objective) {
  residuals(map, r, &jac);
  double e = objective(map, r);
  int taken = 0;
  for (int it = 0; it < iterations; ++it) {
    const Eigen::VectorXd step = step_of(map, geman_mcclure_weights(points, r, c2));
    if (!step.allFinite()) break;
    bool accepted = false;
    double e_new = e;
    for (double alpha = 1; alpha > 1e-3 && !accepted; alpha *= 0.5) {
      std::optional<GlobalMap> moved = trial(map, step, alpha);
      if (!moved) continue;
      Eigen::VectorXd r_trial;
      residuals(*moved, r_trial, nullptr);
      e_new = objective(*moved, r_trial);
      if (e_new < e) map = std::move(*moved), accepted = true;
    }
    if (!accepted) break;
    ++taken;
    const bool settled = e - e_new < 1e-6 * (1 + e);
    e = e_new;
    residuals(map, r, &jac);
    if (settled) break;
  }
  return taken;
}

}  // namespace

namespace detail {

std::vector<GlobalMap> refine_global_map(GlobalMap map, const SurfaceSamples& surface,
                                         const std::vector<AttractivePoint>& points,
                                         const AffineFitOptions& o, bool anneal) {
  std::vector<GlobalMap> ends;
  const int m = static_cast<int>(points.size());
  Eigen::Matrix3Xd p(3, m);
  for (int k = 0; k < m; ++k)
    p.col(k) = points[k].p_mm;
  const double extent2 = (p.colwise() - map.shears.centre).colwise().squaredNorm().mean();
  const double lambda_a_final = o.regularisation * m * extent2;
  const double lambda_c_final =
      o.shear_regularisation * m * extent2 * extent2;  // coefficients are 1/mm
  const Eigen::Vector3d centroid = surface.points.rowwise().mean();

  std::vector<int> match(m);
  std::vector<double> r(m), w;
  const MappedSampleSearch search(surface.points);
  using Vec21 = Eigen::Matrix<double, 21, 1>;
  auto basis = [](const Eigen::Vector3d& u) {  // d(shear image)/dc at u: 3 x 9
    Eigen::Matrix<double, 3, 9> b = Eigen::Matrix<double, 3, 9>::Zero();
    b(0, 0) = u.y() * u.y(), b(0, 1) = u.z() * u.z(), b(0, 2) = u.y() * u.z();
    b(1, 3) = u.x() * u.x(), b(1, 4) = u.z() * u.z(), b(1, 5) = u.x() * u.z();
    b(2, 6) = u.x() * u.x(), b(2, 7) = u.y() * u.y(), b(2, 8) = u.x() * u.y();
    return b;
  };
  StiffnessSchedule schedule{anneal ? 4 : 1, o.iterations};
  // The schedule ends the loop (at most levels x iterations steps), always just after the
  // current map's residuals are measured, so that each map kept carries its own RMS.
  for (;; ++schedule.steps) {
    const double lambda_a = lambda_a_final * schedule.factor(),
                 lambda_c = lambda_c_final * schedule.factor();
    search.nearest(map, p, match, r);
    const double rms = robust_weights(r, points, o.outlier_mads, w);
    const bool settled = schedule.steps > 0 && std::abs(map.rms_after_mm - rms) < 1e-5 * (1 + rms);
    map.rms_after_mm = rms;
    map.affine.rms_after_mm = rms;
    const int level = schedule.level;
    const bool go_on = schedule.go_on(settled);
    if (!go_on || schedule.level != level) ends.push_back(map);
    if (!go_on) break;
    // Linearised image of sample s: a s + t + B(u) c, u = the current affine image - centre.
    const Vec21 theta = solve_matched_step<9>(
        surface, p, match, w, map.affine.a.inverse().transpose(), o.point_to_point, lambda_a,
        lambda_c, [&](int j) {
          return basis(map.affine.a * surface.points.col(j) + map.affine.t - map.shears.centre);
        });
    Eigen::Matrix3d a;
    a << theta.segment<3>(0).transpose(), theta.segment<3>(3).transpose(),
        theta.segment<3>(6).transpose();
    Eigen::Vector3d t = theta.segment<3>(9);
    const double det = a.determinant();
    if (!(det > 0) || !theta.allFinite()) {  // degenerate: keep the last good map
      ends.push_back(map);
      break;
    }
    const Eigen::Vector3d image = a * centroid + t;  // det(a) = 1 about the body's centre
    a /= std::cbrt(det);
    t = image - a * centroid;
    map.affine.a = a;
    map.affine.t = t;
    map.shears.c.head<9>() = theta.segment<9>(12);
    ++map.affine.iterations;
  }
  return ends;
}

std::vector<GlobalMap> fit_to_distance(GlobalMap map, const geometry::SignedDistance& distance,
                                       const SurfaceSamples& surface,
                                       const std::vector<AttractivePoint>& points,
                                       const AffineFitOptions& o, bool with_shears,
                                       bool on_constraint) {
  const int m = static_cast<int>(points.size());
  const int n = with_shears ? 12 + QuadraticShears::kCount : 12;  // a (row-major), t, c
  using VecX = Eigen::VectorXd;
  const Eigen::Vector3d centroid = surface.points.rowwise().mean();
  double extent2 = 0;
  for (const AttractivePoint& p : points)
    extent2 += (p.p_mm - map.shears.centre).squaredNorm() / m;
  const double lambda_a_final = o.regularisation * m * extent2;
  const double lambda_c_final = o.shear_regularisation * m * extent2 * extent2;
  auto theta_of = [n, with_shears](const GlobalMap& g) {
    VecX th(n);
    for (int i = 0; i < 3; ++i)
      for (int j = 0; j < 3; ++j)
        th(3 * i + j) = g.affine.a(i, j);
    th.segment<3>(9) = g.affine.t;
    if (with_shears) th.tail<QuadraticShears::kCount>() = g.shears.c;
    return th;
  };
  auto map_of = [&](const VecX& th) {  // det(a) = 1 by scaling about the body's centre
    GlobalMap g = map;
    for (int i = 0; i < 3; ++i)
      for (int j = 0; j < 3; ++j)
        g.affine.a(i, j) = th(3 * i + j);
    g.affine.t = th.segment<3>(9);
    if (with_shears) g.shears.c = th.tail<QuadraticShears::kCount>();
    const double det = g.affine.a.determinant();
    if (!(det > 0) || !th.allFinite()) return std::optional<GlobalMap>();
    const Eigen::Vector3d image = g.affine.a * centroid + g.affine.t;
    g.affine.a /= std::cbrt(det);
    g.affine.t = image - g.affine.a * centroid;
    return std::optional<GlobalMap>(g);
  };
  VecX identity = VecX::Zero(n);
  identity(0) = identity(4) = identity(8) = 1;
  // The body's centre's image is (centre_shift theta): a c + t. The pull is on its
  // displacement, not on t: t alone is the image of the patient's coordinate origin, and
  // pulling it made the fit of an organ far from that origin stiff against any change
  // moving it (300 mm away, the same cube and points gave a map 7.8 mm different). Since
  // centre_shift identity = c, that displacement is centre_shift (theta - identity), and
  // all the pulls are one quadratic form in theta - identity (`pull` below).
  Eigen::MatrixXd centre_shift = Eigen::MatrixXd::Zero(3, n);
  for (int i = 0; i < 3; ++i) {
    for (int j = 0; j < 3; ++j)
      centre_shift(i, 3 * i + j) = centroid(j);
    centre_shift(i, 9 + i) = 1;
  }
  // Residuals (mm) and, when asked, their Jacobian (m x n).
  auto residuals = [&](const GlobalMap& g, VecX& r, Eigen::MatrixXd* jac) {
    const Eigen::Matrix3d b = g.affine.a.inverse();
    r.resize(m);
    if (jac) jac->resize(m, n);
#pragma omp parallel for schedule(static)
    for (int k = 0; k < m; ++k) {
      const auto [rk, q, gp, nu] = mapped_distance(g, b, distance, points[k].p_mm);
      r(k) = rk;
      if (!jac) continue;
      for (int i = 0; i < 3; ++i)
        for (int j = 0; j < 3; ++j)
          (*jac)(k, 3 * i + j) = -gp(i) * q(j) / nu;  // d(a^-1)/da_ij = -b e_i e_j^T b
      jac->block<1, 3>(k, 9) = -gp.transpose() / nu;
      for (int l = 12; l < n; ++l) {  // the nested inverse shears, by central differences
        const double h = 1e-6;
        QuadraticShears plus = g.shears, minus = g.shears;
        plus.c(l - 12) += h, minus.c(l - 12) -= h;
        (*jac)(k, l) =
            gp.dot(plus.inverse(points[k].p_mm) - minus.inverse(points[k].p_mm)) / (2 * h * nu);
      }
    }
  };
  std::vector<GlobalMap> ends;
  for (int level = 0; level < 4; ++level) {
    const double factor = std::pow(10.0, 3 - level);
    // Graduated non-convexity: the robust scale starts 8x the stated one, so that a large
    // change (points 10 mm off) is followed before anything is taken for an outlier.
    const double scale = o.distance_scale_mm * std::pow(2.0, 3 - level), c2 = scale * scale;
    VecX lambda = VecX::Constant(n, lambda_a_final * factor);
    lambda.segment<3>(9).setZero();  // t is pulled through the centre's displacement
    if (with_shears) lambda.tail<QuadraticShears::kCount>().setConstant(lambda_c_final * factor);
    const double lambda_centre = lambda_a_final * factor;  // per mm^2
    Eigen::MatrixXd pull = lambda_centre * centre_shift.transpose() * centre_shift;
    pull.diagonal() += lambda;
    auto objective = [&](const GlobalMap& g, const VecX& r) {
      const VecX d = theta_of(g) - identity;
      return 0.5 * geman_mcclure(points, r, c2) + 0.5 * d.dot(pull * d);
    };
    VecX r;
    Eigen::MatrixXd jac;
    map.affine.iterations += robust_gauss_newton(
        map, r, jac, points, c2, o.iterations,
        [&](const GlobalMap& g, const VecX& w) -> VecX {
          Eigen::MatrixXd h = jac.transpose() * w.asDiagonal() * jac;
          h += pull;
          const VecX gradient =
              jac.transpose() * w.cwiseProduct(r) + pull * (theta_of(g) - identity);
          if (!on_constraint) return VecX(h.ldlt().solve(-gradient));
          return solve_on_constraint(h, -gradient, unit_determinant_normal(g.affine.a, n), 0.0);
        },
        [&](const GlobalMap& g, const VecX& step, double alpha) {
          return map_of(theta_of(g) + alpha * step);
        },
        residuals, objective);
    map.rms_after_mm = map.affine.rms_after_mm =
        nearest_sample_rms(map, surface, points, o.outlier_mads);
    ends.push_back(map);
  }
  return ends;
}

RidgeSystem::RidgeSystem(const Eigen::MatrixXd& jac, const Eigen::VectorXd& w, double lambda,
                         const std::vector<int>* row_order)
    : jac_(jac), w_(w), lambda_(lambda), in_points_(jac.rows() < jac.cols()) {
  if (in_points_) {
    Eigen::MatrixXd s = jac * jac.transpose() * w.asDiagonal();
    s.diagonal().array() += lambda;
    lu_.compute(s);
  } else {
    llt_.compute(normal_matrix(jac, w, lambda, row_order));
  }
}

Eigen::VectorXd RidgeSystem::solve(const Eigen::VectorXd& g) const {
  if (!in_points_) return llt_.solve(g);
  return (g - jac_.transpose() * w_.cwiseProduct(lu_.solve(jac_ * g))) / lambda_;
}

Eigen::VectorXd RidgeSystem::leverages() const {
  const Eigen::Index m = jac_.rows();
  if (in_points_) {
    // J S^-1 J^T W = K (K + lambda I)^-1 = I - lambda (K + lambda I)^-1, K = J J^T W.
    const Eigen::MatrixXd inverse = lu_.solve(Eigen::MatrixXd::Identity(m, m));
    Eigen::VectorXd h = (1.0 - lambda_ * inverse.diagonal().array()).cwiseMax(0.0).cwiseMin(1.0);
    for (Eigen::Index k = 0; k < m; ++k)
      if (w_(k) == 0) h(k) = 0;  // w_k times the rest: not left to rounding
    return h;
  }
  // h_k = w_k |L^-1 J_k^T|^2 for S = L L^T: L solved against blocks of J^T's columns on
  // threads.
  constexpr Eigen::Index kBlock = 64;
  const Eigen::Index blocks = (m + kBlock - 1) / kBlock;
  Eigen::VectorXd h(m);
  const auto l = llt_.matrixL();
#pragma omp parallel for schedule(dynamic, 1)
  for (Eigen::Index b = 0; b < blocks; ++b) {
    const Eigen::Index k0 = b * kBlock, width = std::min(kBlock, m - k0);
    Eigen::MatrixXd x = jac_.middleRows(k0, width).transpose();
    l.solveInPlace(x);
    h.segment(k0, width) =
        (w_.segment(k0, width).array() * x.colwise().squaredNorm().transpose().array())
            .cwiseMin(1.0);
  }
  return h;
}

Eigen::MatrixXd RidgeSystem::normal_matrix(const Eigen::MatrixXd& jac, const Eigen::VectorXd& w,
                                           double lambda, const std::vector<int>* row_order) {
  // Row by row, J^T W J is a rank-one update per point over its nonzeros (a fifth of a
  // lung's 1,596 heights): 25,000 entries of an n x n matrix read and written per point,
  // bound by memory. Rows taken in groups instead, the consecutive ones (in row_order)
  // whose nonzeros' union stays within 1.5 times the largest row's: a group's block
  // G^T W G is one dense product over that union, added to the matrix once.
  const Eigen::Index m = jac.rows(), n = jac.cols();
  std::vector<int> rows;
  if (row_order) {
    for (int k : *row_order)
      if (w(k) != 0) rows.push_back(k);
  } else {
    for (Eigen::Index k = 0; k < m; ++k)
      if (w(k) != 0) rows.push_back(static_cast<int>(k));
  }
  // Each row's nonzeros (column, value), read down J's columns (contiguous), a run of
  // rows per thread.
  std::vector<std::vector<std::pair<int, double>>> by_row(static_cast<size_t>(m));
#pragma omp parallel
  {
    const int threads = omp_get_num_threads(), me = omp_get_thread_num();
    const Eigen::Index lo = m * me / threads, hi = m * (me + 1) / threads;
    for (Eigen::Index c = 0; c < n; ++c) {
      const double* column = jac.col(c).data();
      for (Eigen::Index k = lo; k < hi; ++k)
        if (column[k] != 0)
          by_row[static_cast<size_t>(k)].push_back({static_cast<int>(c), column[k]});
    }
  }
  std::vector<std::vector<std::pair<int, double>>> nonzeros(rows.size());
  for (size_t r = 0; r < rows.size(); ++r)
    nonzeros[r] = std::move(by_row[static_cast<size_t>(rows[r])]);
  // Groups: [starts[g], starts[g + 1]) of `rows`.
  constexpr size_t kMostRows = 64;
  constexpr double kUnionOverRow = 1.5;
  std::vector<size_t> starts;
  {
    std::vector<char> in_union(static_cast<size_t>(n), 0);
    std::vector<int> members;
    size_t largest = 0;
    for (size_t r = 0; r < rows.size(); ++r) {
      const auto& nz = nonzeros[r];
      size_t added = 0;
      for (const auto& [c, value] : nz)
        added += !in_union[static_cast<size_t>(c)];
      const size_t larger = std::max(largest, nz.size());
      const bool fits = !starts.empty() && r - starts.back() < kMostRows &&
                        static_cast<double>(members.size() + added) <= kUnionOverRow * larger;
      if (!fits) {
        for (int c : members)
          in_union[static_cast<size_t>(c)] = 0;
        members.clear(), largest = 0;
        starts.push_back(r);
      }
      for (const auto& [c, value] : nz)
        if (!in_union[static_cast<size_t>(c)])
          in_union[static_cast<size_t>(c)] = 1, members.push_back(c);
      largest = std::max(largest, nz.size());
    }
    starts.push_back(rows.size());
  }
  const auto groups = static_cast<long long>(starts.size()) - 1;
  // Each thread sums its own groups; the parts are added in thread order afterwards, so
  // the sum is the same from run to run.
  std::vector<Eigen::MatrixXd> parts;
#pragma omp parallel
  {
#pragma omp single
    parts.assign(static_cast<size_t>(omp_get_num_threads()), Eigen::MatrixXd::Zero(n, n));
    Eigen::MatrixXd& part = parts[static_cast<size_t>(omp_get_thread_num())];
    std::vector<int> local(static_cast<size_t>(n), -1), columns;
    Eigen::MatrixXd g, gw, block;
#pragma omp for schedule(static)
    for (long long group = 0; group < groups; ++group) {
      const size_t first = starts[static_cast<size_t>(group)];
      const size_t last = starts[static_cast<size_t>(group) + 1];
      columns.clear();
      for (size_t r = first; r < last; ++r)
        for (const auto& [c, value] : nonzeros[r])
          if (local[static_cast<size_t>(c)] < 0)
            local[static_cast<size_t>(c)] = 0, columns.push_back(c);
      std::sort(columns.begin(), columns.end());  // the block's lower triangle is the matrix's
      const auto u = static_cast<Eigen::Index>(columns.size());
      for (Eigen::Index a = 0; a < u; ++a)
        local[static_cast<size_t>(columns[static_cast<size_t>(a)])] = static_cast<int>(a);
      const auto height = static_cast<Eigen::Index>(last - first);
      g.setZero(height, u);
      for (size_t r = first; r < last; ++r)
        for (const auto& [c, value] : nonzeros[r])
          g(static_cast<Eigen::Index>(r - first), local[static_cast<size_t>(c)]) = value;
      gw = g;
      for (size_t r = first; r < last; ++r)
        gw.row(static_cast<Eigen::Index>(r - first)) *= w(rows[r]);
      block.setZero(u, u);
      block.triangularView<Eigen::Lower>() += g.transpose() * gw;
      for (Eigen::Index b = 0; b < u; ++b) {
        double* column = part.col(columns[static_cast<size_t>(b)]).data();
        for (Eigen::Index a = b; a < u; ++a)
          column[columns[static_cast<size_t>(a)]] += block(a, b);
      }
      for (int c : columns)
        local[static_cast<size_t>(c)] = -1;
    }
  }
  Eigen::MatrixXd s = std::move(parts[0]);
  for (size_t t = 1; t < parts.size(); ++t)
    s += parts[t];
  s.diagonal().array() += lambda;
  return s;  // its lower triangle: what Cholesky reads
}

std::vector<int> spatial_order(const std::vector<AttractivePoint>& points) {
  std::vector<int> order(points.size());
  if (points.empty()) return order;
  Eigen::Vector3d lo = points[0].p_mm;
  for (const auto& p : points)
    lo = lo.cwiseMin(p.p_mm);
  // 1 mm cells; morton_code reads 21 bits a coordinate: 2 km.
  std::vector<std::uint64_t> code(points.size());
  for (size_t k = 0; k < points.size(); ++k) {
    const Eigen::Vector3d c = (points[k].p_mm - lo).cwiseMax(0.0).cwiseMin(2e6);
    code[k] =
        geometry::morton_code(static_cast<std::uint64_t>(c.x()), static_cast<std::uint64_t>(c.y()),
                              static_cast<std::uint64_t>(c.z()));
    order[k] = static_cast<int>(k);
  }
  std::stable_sort(order.begin(), order.end(), [&code](int a, int b) {
    return code[static_cast<size_t>(a)] < code[static_cast<size_t>(b)];
  });
  return order;
}

namespace {
/// A part of the map that is linear, to first order, in its parameters (the shear fields'
/// heights, the flow's potentials), fitted with the rest held: robust Gauss-Newton on the
/// points' mapped_distance, Geman-McClure weights of scale distance_scale_mm, the
/// parameters pulled towards none by `lambda` (ridge; solved in the points' space when
/// they outnumber the points). `parameters(g)` is the part's vector in map g; `row(g, p, d,
/// jac_row)` writes point p's row of d r / d parameters (d: its MappedDistance); rows are
/// made on threads, so `row` keeps no state between calls.
template <class Parameters, class Row>
GlobalMap fit_linearised_part(GlobalMap map, const geometry::SignedDistance& distance,
                              const std::vector<AttractivePoint>& points, const AffineFitOptions& o,
                              double lambda, Parameters&& parameters, Row&& row,
                              LinearisedFit& judged) {
  judged = LinearisedFit{};
  const int m = static_cast<int>(points.size());
  const int n = static_cast<int>(parameters(map).size());
  if (n == 0 || m == 0) return map;
  using VecX = Eigen::VectorXd;
  const double c2 = o.distance_scale_mm * o.distance_scale_mm;
  auto residuals = [&](const GlobalMap& g, VecX& r, Eigen::MatrixXd* jac) {
    const Eigen::Matrix3d b = g.affine.a.inverse();
    r.resize(m);
    if (jac) jac->setZero(m, n);
#pragma omp parallel for schedule(static)
    for (int k = 0; k < m; ++k) {
      const MappedDistance d = mapped_distance(g, b, distance, points[k].p_mm);
      r(k) = d.r;
      if (jac) row(g, points[k].p_mm, d, jac->row(k));
    }
  };
  auto objective = [&](const GlobalMap& g, const VecX& r) {
    return 0.5 * geman_mcclure(points, r, c2) + 0.5 * lambda * parameters(g).squaredNorm();
  };
  const std::vector<int> order = spatial_order(points);
  VecX r;
  Eigen::MatrixXd jac;
  map.affine.iterations += robust_gauss_newton(
      map, r, jac, points, c2, o.iterations,
      [&](const GlobalMap& g, const VecX& w) -> VecX {
        return -RidgeSystem(jac, w, lambda, &order)
                    .solve(jac.transpose() * w.cwiseProduct(r) + lambda * parameters(g));
      },
      [&](const GlobalMap& g, const VecX& step, double alpha) {
        std::optional<GlobalMap> moved = g;
        parameters(*moved) += alpha * step;
        return moved;
      },
      residuals, objective);
  const VecX w = geman_mcclure_weights(points, r, c2);
  const VecX h = RidgeSystem(jac, w, lambda, &order).leverages();
  judged.effective_dof = h.sum();
  judged.left_out_mm.resize(static_cast<size_t>(m));
  for (int k = 0; k < m; ++k)  // h = 1 only where no ridge holds it (lambda > 0 here)
    judged.left_out_mm[static_cast<size_t>(k)] = r(k) / std::max(1 - h(k), 1e-12);
  return map;
}
}  // namespace

GlobalMap fit_shear_fields(GlobalMap map, const geometry::SignedDistance& distance,
                           const Eigen::Matrix3Xd& mapped_surface,
                           const std::vector<AttractivePoint>& points, const AffineFitOptions& o,
                           LinearisedFit& judged) {
  map.fields = ShearFields::over(mapped_surface.rowwise().minCoeff(),
                                 mapped_surface.rowwise().maxCoeff(), o.field_sigma_mm);
  return fit_linearised_part(
      std::move(map), distance, points, o, std::max(o.field_stiffness, 1e-9),
      [](auto& g) -> auto& { return g.fields.weights; },
      [&](const GlobalMap& g, const Eigen::Vector3d& p, const MappedDistance& d, auto jac_row) {
        std::vector<std::pair<int, double>> near;  // a point's own: rows on threads
        for (int a = 0; a < 3; ++a) {              // field a's bumps move p along a
          g.fields.bumps(a, p, near);
          for (const auto& [index, value] : near)
            jac_row(index) = -d.gp(a) * value / d.nu;
        }
      },
      judged);
}

GlobalMap fit_flow(GlobalMap map, const geometry::SignedDistance& distance,
                   const Eigen::Matrix3Xd& mapped_surface,
                   const std::vector<AttractivePoint>& points, const AffineFitOptions& o,
                   LinearisedFit& judged) {
  map.flow = IncompressibleFlow::over(mapped_surface.rowwise().minCoeff(),
                                      mapped_surface.rowwise().maxCoeff(), o.flow_sigma_mm);
  // Its Jacobian is dense here: three potentials per node of a 3D grid (41k on a 2 L
  // lung) by the points; beyond 5e7 entries (400 MB) the flow is left out.
  if (static_cast<double>(points.size()) * static_cast<double>(map.flow.potentials.size()) > 5e7) {
    map.flow = IncompressibleFlow{};
    judged = LinearisedFit{};
    return map;
  }
  // d r / d a_n = -(gp x g_n) / nu: the flow's inverse moves p by -v(p) to first order,
  // and v(p) = sum_n g_n x a_n.
  return fit_linearised_part(
      std::move(map), distance, points, o,
      std::max(o.field_stiffness, 1e-9) * IncompressibleFlow::stiffness_per_field_stiffness(),
      [](auto& g) -> auto& { return g.flow.potentials; },
      [&](const GlobalMap& g, const Eigen::Vector3d& p, const MappedDistance& d, auto jac_row) {
        std::vector<std::pair<int, Eigen::Vector3d>> near;  // a point's own: rows on threads
        g.flow.basis_gradients(p, near);
        for (const auto& [node, gradient] : near)
          jac_row.template segment<3>(3 * node) = -d.gp.cross(gradient).transpose() / d.nu;
      },
      judged);
}

}  // namespace detail
}  // namespace organfit::fitting
