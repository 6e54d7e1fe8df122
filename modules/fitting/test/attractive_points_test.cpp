#include "organfit/fitting/attractive_points.h"

#include <gtest/gtest.h>
#include <omp.h>

#include <Eigen/Geometry>
#include <Eigen/QR>
#include <algorithm>
#include <cmath>

#include "organfit/fitting/spread_force.h"
#include "organfit/particles/lattice_fill.h"

namespace organfit::fitting {
namespace {

using particles::Forces;
using particles::State;

class PaperForceTest : public ::testing::Test {
 protected:
  void SetUp() override {
    params_.r0_mm = 2.0;
    law_ = std::make_unique<particles::LennardJones>(params_);
    a_ = particles::fcc_equilibrium_spacing(*law_);
    state_ = State(particles::fill_ellipsoid({30, 20, 20}, {0, 0, 0}, a_));
    force_params_.total_force_factor = 1000;  // no cap unless a test asks for it
  }
  Forces forces_of_spread(SpreadAttractiveForce& term) {
    Forces f = Forces::Zero(3, state_.size());
    term.add_forces(state_, f, false);
    return f;
  }
  Forces forces_of(PaperAttractiveForce& term) {
    Forces f = Forces::Zero(3, state_.size());
    term.add_forces(state_, f, false);
    return f;
  }
  double rho() const { return 0.5 * params_.r0_mm; }
  particles::CohesionParams params_;
  std::unique_ptr<particles::LennardJones> law_;
  double a_ = 0;
  State state_;
  PaperForceParams force_params_;
};

TEST_F(PaperForceTest, EpicentreReceivesExactlyFMaxKTowardsThePoint) {
  const Eigen::Vector3d p(15 + 5, 0.3, -0.2);
  PaperAttractiveForce term({{p, 1.0}}, *law_, rho(), force_params_, rho());
  const Forces f = forces_of(term);
  const PointStatus& st = term.status()[0];
  ASSERT_GE(st.epicentre, 0);
  // W of the epicentre by brute force: the reference for the O(N) count the force uses.
  int w = 0;
  for (int j = 0; j < state_.size(); ++j)
    if (j != st.epicentre &&
        (state_.x.col(j) - state_.x.col(st.epicentre)).norm() < 1.3 * params_.r0_mm)
      ++w;
  EXPECT_EQ(w, first_shell_counts(state_.x, 1.3 * params_.r0_mm)[st.epicentre]);
  EXPECT_GE(w, 5);
  EXPECT_LE(w, 12);
  EXPECT_NEAR(st.f_max_k, 0.5 * w * law_->f_max(), 1e-12);
  EXPECT_NEAR(f.col(st.epicentre).norm(), st.f_max_k, 1e-9 * st.f_max_k);
  const Eigen::Vector3d u = (p - state_.x.col(st.epicentre)).normalized();
  EXPECT_NEAR(f.col(st.epicentre).normalized().dot(u), 1.0, 1e-12);
  EXPECT_FALSE(st.inside_model);
}

TEST_F(PaperForceTest, FirstShellCountsOfListedParticlesAreTheBruteForceCounts) {
  const double shell = 1.3 * params_.r0_mm;
  std::vector<int> listed;
  for (int i = 0; i < state_.size(); i += 7)
    listed.push_back(i);
  const std::vector<int> w = first_shell_counts(state_.x, shell, listed);
  ASSERT_EQ(static_cast<int>(w.size()), state_.size());
  int interior = 0;
  for (int i = 0; i < state_.size(); ++i) {
    int brute = 0;
    for (int j = 0; j < state_.size(); ++j)
      brute += j != i && (state_.x.col(j) - state_.x.col(i)).norm() < shell;
    EXPECT_EQ(w[i], i % 7 == 0 ? brute : 0) << i;
    interior += i % 7 == 0 && brute == 12;  // fcc bulk
  }
  EXPECT_GT(interior, 10);
}

TEST_F(PaperForceTest, OthersFallOffAsTheRatioToThePowerAlphaMinusOne) {
  force_params_.alpha = 3.0;
  force_params_.influence_radius_min_r0 = 2.5;
  const Eigen::Vector3d p(20, 0, 0);
  PaperAttractiveForce term({{p, 1.0}}, *law_, rho(), force_params_, rho());
  const Forces f = forces_of(term);
  const PointStatus& st = term.status()[0];
  ASSERT_GT(st.influence_count, 3);
  const std::vector<int> shells = first_shell_counts(state_.x, 1.3 * params_.r0_mm);
  int checked = 0, capped = 0;
  for (int i = 0; i < state_.size(); ++i) {
    if (i == st.epicentre || f.col(i).norm() == 0) continue;
    const double r = (p - state_.x.col(i)).norm();
    // Eq. 5's fall-off, capped by what the particle's own neighbours hold (W(i) F_max / 2).
    const double cap = 0.5 * shells[i] * law_->f_max();
    const double expected =
        std::min(cap, st.f_max_k * std::pow((st.d_min_mm - rho()) / (r - rho()), 2.0));
    EXPECT_NEAR(f.col(i).norm(), expected, 1e-9 * st.f_max_k) << i;
    EXPECT_LT(f.col(i).norm(), st.f_max_k);
    capped += expected == cap;
    ++checked;
  }
  EXPECT_EQ(checked + 1, st.influence_count);
  EXPECT_LT(capped, checked);  // most follow the fall-off law itself
}

TEST_F(PaperForceTest, TotalForceCapScalesTheOthersNotTheEpicentre) {
  force_params_.total_force_factor = 1.5;
  force_params_.influence_radius_min_r0 = 3.0;
  PaperAttractiveForce term({{Eigen::Vector3d(20, 0, 0), 1.0}}, *law_, rho(), force_params_, rho());
  const Forces f = forces_of(term);
  const PointStatus& st = term.status()[0];
  double total = 0;
  for (int i = 0; i < state_.size(); ++i)
    total += f.col(i).norm();
  EXPECT_NEAR(total, 1.5 * st.f_max_k, 1e-9 * st.f_max_k);
  EXPECT_NEAR(f.col(st.epicentre).norm(), st.f_max_k, 1e-9 * st.f_max_k);
}

TEST_F(PaperForceTest, ZeroOnArrivalAndForAPointOnAParticle) {
  // Case 2: the point lies inside a skin particle: no force at all.
  PaperAttractiveForce on_particle({{state_.x.col(0) + Eigen::Vector3d(0.2, 0, 0), 1.0}}, *law_,
                                   rho(), force_params_, rho());
  EXPECT_EQ(forces_of(on_particle).norm(), 0.0);
  EXPECT_TRUE(on_particle.status()[0].reached);
  // Arrival: the epicentre moved onto its point (the skin not recomputed): all forces vanish.
  const Eigen::Vector3d p(15 + 1.5, 0, 0);
  PaperAttractiveForce term({{p, 1.0}}, *law_, rho(), force_params_,
                            10.0 /* coarse skin: no recompute */);
  forces_of(term);
  const int e = term.status()[0].epicentre;
  state_.x.col(e) = p + Eigen::Vector3d(0.5 * rho(), 0, 0);
  EXPECT_EQ(forces_of(term).norm(), 0.0);
  EXPECT_TRUE(term.status()[0].reached);
}

TEST_F(PaperForceTest, InsidePointPushesTheSkinInwardsTowardsIt) {
  const Eigen::Vector3d p(9, 0, 0);  // inside, 6 mm below the x = 15 mm surface
  force_params_.influence_radius_min_r0 = 2.0;
  PaperAttractiveForce term({{p, 1.0}}, *law_, rho(), force_params_, rho());
  const Forces f = forces_of(term);
  EXPECT_TRUE(term.status()[0].inside_model);
  int pushed = 0;
  for (int i = 0; i < state_.size(); ++i) {
    if (f.col(i).norm() == 0) continue;
    // Pushed towards the point: into the body (skin around the cap and the sides nearby).
    EXPECT_NEAR(f.col(i).normalized().dot((p - state_.x.col(i)).normalized()), 1.0, 1e-12);
    ++pushed;
  }
  EXPECT_GT(pushed, 0);
}

TEST_F(PaperForceTest, FarOutlierIsRejectedAndExertsNoForce) {
  PaperAttractiveForce term({{Eigen::Vector3d(300, 0, 0), 1.0}, {Eigen::Vector3d(18, 0, 0), 1.0}},
                            *law_, rho(), force_params_, rho());
  const Forces f = forces_of(term);
  EXPECT_TRUE(term.status()[0].rejected);
  EXPECT_FALSE(term.status()[1].rejected);
  EXPECT_GT(f.norm(), 0.0);
  EXPECT_LT(f.colwise().norm().maxCoeff(), 1.0001 * term.status()[1].f_max_k);
}

// Points on the +y half of the body's ellipsoid, the `moved` of them nearest `spot`
// pushed `off_mm` outwards along the normal (their indices in `which`).
std::vector<AttractivePoint> half_ellipsoid_points(const Eigen::Vector3d& spot, int moved,
                                                   double off_mm, std::vector<char>& which) {
  std::vector<AttractivePoint> pts;
  std::vector<Eigen::Vector3d> normals;
  const Eigen::Vector3d semi(15, 10, 10);
  for (int i = 0; i < 12; ++i)
    for (int j = 1; j <= 6; ++j) {
      const double phi = M_PI * i / 11.0, theta = M_PI * j / 7.0;  // y >= 0 half
      const Eigen::Vector3d u(std::cos(phi) * std::sin(theta), std::sin(phi) * std::sin(theta),
                              std::cos(theta));
      const Eigen::Vector3d p = semi.cwiseProduct(u);
      pts.push_back({p, 1.0});
      normals.push_back(p.cwiseQuotient(semi.cwiseProduct(semi)).normalized());
    }
  std::vector<int> order(pts.size());
  for (size_t k = 0; k < order.size(); ++k)
    order[k] = static_cast<int>(k);
  std::sort(order.begin(), order.end(), [&](int l, int r) {
    return (pts[l].p_mm - spot).norm() < (pts[r].p_mm - spot).norm();
  });
  which.assign(pts.size(), 0);
  for (int q = 0; q < moved; ++q)
    pts[order[q]].p_mm += off_mm * normals[order[q]], which[order[q]] = 1;
  return pts;
}

// The spread force's neighbour test: a lone point 3.5 mm off the surface (within the
// 2 r0 that the global rule lets pass) is rejected; a dent of the same depth shown by
// a group of neighbouring points is data.
TEST_F(PaperForceTest, SpreadForceRejectsALoneJumpButNotACoherentDent) {
  const Eigen::Vector3d spot(0, 10, 0);
  std::vector<char> lone_moved, dent_moved;
  const auto lone = half_ellipsoid_points(spot, 1, 3.5, lone_moved);
  const auto dent = half_ellipsoid_points(spot, 7, 3.5, dent_moved);
  for (const auto* pts : {&lone, &dent}) {
    SpreadAttractiveForce term(*pts, *law_, rho(), SpreadForceParams{}, rho());
    forces_of_spread(term);
    for (size_t k = 0; k < pts->size(); ++k)
      EXPECT_EQ(term.status()[k].rejected, pts == &lone && lone_moved[k])
          << (pts == &lone ? "lone" : "dent") << " point " << k;
    // Without the test nothing is rejected.
    SpreadForceParams off;
    off.consistency_threshold = 0;
    SpreadAttractiveForce plain(*pts, *law_, rho(), off, rho());
    forces_of_spread(plain);
    for (const auto& st : plain.status())
      EXPECT_FALSE(st.rejected);
  }
}

/// A body of r0 = 2 mm particles filling the ellipsoid of semi-axes `semi_mm` on its fcc
/// lattice, and `count` points spread evenly over that ellipsoid (a Fibonacci sphere
/// scaled), each with its outward normal.
struct EllipsoidCase {
  particles::CohesionParams params;
  particles::LennardJones law;
  double rho;
  State state;
  std::vector<Eigen::Vector3d> on, normal;
  EllipsoidCase(const Eigen::Vector3d& semi_mm, int count)
      : params(with_r0(2.0)),
        law(params),
        rho(0.5 * params.r0_mm),
        state(particles::fill_ellipsoid(2 * semi_mm, {0, 0, 0},
                                        particles::fcc_equilibrium_spacing(law))) {
    for (int k = 0; k < count; ++k) {
      const double z = 1 - 2 * (k + 0.5) / count, ring = std::sqrt(1 - z * z);
      const double phi = k * M_PI * (3 - std::sqrt(5.0));
      on.push_back(
          semi_mm.cwiseProduct(Eigen::Vector3d(ring * std::cos(phi), ring * std::sin(phi), z)));
      normal.push_back(on.back().cwiseQuotient(semi_mm.cwiseProduct(semi_mm)).normalized());
    }
  }
  static particles::CohesionParams with_r0(double r0_mm) {
    particles::CohesionParams p;
    p.r0_mm = r0_mm;
    return p;
  }
};

/// The net force and torque about the centroid of forces `f` on `state`, and the sum of
/// their sizes and of their moments' sizes (the scales to compare them with).
struct NetLoad {
  Eigen::Vector3d force = Eigen::Vector3d::Zero(), torque = Eigen::Vector3d::Zero();
  double force_scale = 0, torque_scale = 0;
};
NetLoad net_load(const State& state, const Forces& f) {
  NetLoad out;
  const Eigen::Vector3d centroid = state.x.rowwise().mean();
  for (int i = 0; i < state.size(); ++i) {
    const Eigen::Vector3d r = state.x.col(i) - centroid;
    out.force += f.col(i);
    out.torque += r.cross(f.col(i));
    out.force_scale += f.col(i).norm();
    out.torque_scale += r.norm() * f.col(i).norm();
  }
  return out;
}

// The spread force on threads: each point's residual and each patch particle's sum run in
// parallel once there are thousands of them; the forces must be those of one thread, bit
// for bit, and the pressure must still take back the patches' whole outward push.
TEST(SpreadForce, ThreadsGiveOneThreadsForcesAndNoNetOutwardPush) {
  // 6,000 points 1.5 mm outside the body's surface, spread evenly.
  const EllipsoidCase body(Eigen::Vector3d(60, 40, 40), 6000);
  std::vector<AttractivePoint> pts;
  for (size_t k = 0; k < body.on.size(); ++k)
    pts.push_back({body.on[k] + 1.5 * body.normal[k], 1.0});
  const int saved = omp_get_max_threads();
  std::vector<Forces> f;
  std::vector<int> skin;
  SpreadForceParams volume_alone;  // the pressure's outward sum, without the pose's hold
  volume_alone.hold_pose = false;
  for (const SpreadForceParams& settings :
       {SpreadForceParams{}, SpreadForceParams{}, volume_alone}) {
    omp_set_num_threads(f.size() == 1 ? 2 : 1);
    SpreadAttractiveForce term(pts, body.law, body.rho, settings, body.rho);
    f.push_back(Forces::Zero(3, body.state.size()));
    term.add_forces(body.state, f.back(), false);
    skin = term.skin().skin();
  }
  omp_set_num_threads(saved);
  ASSERT_GE(skin.size(), 4096u);  // the threaded paths ran
  EXPECT_EQ((f[0] - f[1]).cwiseAbs().maxCoeff(), 0.0);
  const Eigen::Vector3d centroid = body.state.x.rowwise().mean();
  double outward = 0, magnitude = 0;
  for (int i : skin) {
    outward += f[2].col(i).dot((body.state.x.col(i) - centroid).normalized());
    magnitude += f[2].col(i).norm();
  }
  EXPECT_GT(magnitude, 0.0);
  EXPECT_LT(std::abs(outward), 1e-9 * magnitude);
  const NetLoad held = net_load(body.state, f[1]);
  EXPECT_LT(held.force.norm(), 1e-9 * held.force_scale);
  EXPECT_LT(held.torque.norm(), 1e-9 * held.torque_scale);
}

// The pose's hold: points 1.5 mm outside one end of the body and turned about its long
// axis pull it one way and turn it; held, the term's forces sum to no force and no torque
// about the centroid (so the body's centroid and turn are the global stage's), while the
// pulls themselves are kept: each patch particle's force is the unheld one less the same
// rigid motion's share as every other particle's.
TEST(SpreadForce, HoldingThePoseTakesBackTheNetForceAndTorqueAsARigidMotion) {
  // The +x third of the surface's points, pushed out and turned.
  const EllipsoidCase body(Eigen::Vector3d(20, 12, 12), 200);
  std::vector<AttractivePoint> pts;
  for (size_t k = 0; k < body.on.size(); ++k) {
    const Eigen::Vector3d& on = body.on[k];
    if (on.x() >= 8)
      pts.push_back(
          {on + 1.5 * body.normal[k] + Eigen::Vector3d(0, -0.1 * on.z(), 0.1 * on.y()), 1.0});
  }
  ASSERT_GE(pts.size(), 30u);
  SpreadForceParams free;
  free.hold_pose = false;
  Forces held_f = Forces::Zero(3, body.state.size()), free_f = Forces::Zero(3, body.state.size());
  SpreadAttractiveForce held(pts, body.law, body.rho, SpreadForceParams{}, body.rho);
  SpreadAttractiveForce unheld(pts, body.law, body.rho, free, body.rho);
  held.add_forces(body.state, held_f, false);
  unheld.add_forces(body.state, free_f, false);
  const NetLoad a = net_load(body.state, free_f), b = net_load(body.state, held_f);
  // Unheld, the pulls move the body (+x) and turn it (+x, as the points are turned).
  EXPECT_GT(a.force.x(), 0.1 * a.force_scale);
  EXPECT_GT(a.torque.x(), 0.01 * a.torque_scale);
  EXPECT_LT(b.force.norm(), 1e-9 * b.force_scale);
  EXPECT_LT(b.torque.norm(), 1e-9 * b.torque_scale);
  // The difference is a rigid motion's forces: f_i = a + alpha x r_i, the same a and alpha
  // for every particle (fitted over all of them, and met at each).
  const Forces d = free_f - held_f;
  const Eigen::Vector3d centroid = body.state.x.rowwise().mean();
  Eigen::MatrixXd system(3 * body.state.size(), 6);
  Eigen::VectorXd rhs(3 * body.state.size());
  for (int i = 0; i < body.state.size(); ++i) {
    const Eigen::Vector3d r = body.state.x.col(i) - centroid;
    Eigen::Matrix3d cross;  // alpha x r = -[r]x alpha
    cross << 0, r.z(), -r.y(), -r.z(), 0, r.x(), r.y(), -r.x(), 0;
    system.block<3, 3>(3 * i, 0).setIdentity();
    system.block<3, 3>(3 * i, 3) = cross;
    rhs.segment<3>(3 * i) = d.col(i);
  }
  const Eigen::VectorXd motion = system.colPivHouseholderQr().solve(rhs);
  EXPECT_LT((system * motion - rhs).cwiseAbs().maxCoeff(), 1e-9 * d.cwiseAbs().maxCoeff());
  EXPECT_GT(motion.head<3>().norm(), 0.0);
  EXPECT_GT(motion.tail<3>().norm(), 0.0);
}

TEST(PaperForce, BadPointsAndParametersAreRefused) {
  particles::LennardJones law{particles::CohesionParams{}};
  PaperForceParams p;
  const double nan = std::numeric_limits<double>::quiet_NaN();
  EXPECT_THROW(PaperAttractiveForce({{Eigen::Vector3d(nan, 0, 0), 1.0}}, law, 0.5, p, 0.5),
               std::invalid_argument);
  EXPECT_THROW(PaperAttractiveForce({{Eigen::Vector3d(0, 0, 0), 0.0}}, law, 0.5, p, 0.5),
               std::invalid_argument);
  p.alpha = 0.5;
  EXPECT_THROW(PaperAttractiveForce({}, law, 0.5, p, 0.5), std::invalid_argument);
}

}  // namespace
}  // namespace organfit::fitting
