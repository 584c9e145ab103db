// Tests of musculoskeletal/knee_loads.h (inverse dynamics of the foot and
// shank) against closed forms. Trials are built in memory with analytic
// coordinates and derivatives, so no filtering or file reading is involved.
#include "musculoskeletal/knee_loads.h"

#include <gtest/gtest.h>

#include <cmath>

#include "common/error.h"

namespace arthrosim::musculoskeletal {
namespace {

constexpr double kG = 9.80665;

GaitTrial empty_trial(int n, double mass = 61.0, double height = 1.65) {
  GaitTrial t;
  t.source = "in-memory";
  t.body_mass_kg = mass;
  t.height_m = height;
  t.rate_hz = 100.0;
  t.time = Eigen::VectorXd::LinSpaced(n, 0.0, (n - 1) / 100.0);
  t.q = Eigen::MatrixXd::Zero(n, kNumTrialCoordinates);
  t.qd = t.q;
  t.qdd = t.q;
  t.has_pelvis = true;
  t.has_grf = true;
  t.grf_force_W = Eigen::MatrixXd::Zero(n, 3);
  t.grf_cop_W = Eigen::MatrixXd::Zero(n, 3);
  t.grf_torque_W = Eigen::MatrixXd::Zero(n, 3);
  return t;
}

// Standing still with the shank vertical (hip flexion = knee flexion, so the
// thigh leans but R_WT = I), ankle flexed by 0.2 rad. Ground reaction F at a
// COP offset (d, ., e) from the ankle, free moment Ty. Closed form, tibia frame
// = world axes:
//   F_ext = F - (m_s + m_f) g e_y
//   M_ext = r x F + (0, Ty, 0) + (0, 0, -x_f m_f g),
// r = COP - knee = (d, -(L_s + h_a), e), x_f = forward offset of the foot COM
// from the knee (the shank COM is straight below the knee: no moment).
// Static: no finite-difference error, only rounding (1e-9 N, N m).
TEST(KneeLoads, StaticStandingClosedForm) {
  GaitTrial t = empty_trial(4);
  const LegModel leg = leg_model_from_anthropometry(61.0, 1.65);
  const double W = 61.0 * kG, a_f = 0.2, d = 0.05, e = 0.02;
  const Eigen::Vector3d F(30.0, W, -15.0);
  for (int i = 0; i < 4; ++i) {
    t.q(i, kPelvisTx) = 0.3;
    t.q(i, kPelvisTy) = 0.95;
    t.q(i, kPelvisTz) = -0.1;
    t.q(i, kHipFlexion) = 0.25;
    t.q(i, kKneeFlexion) = 0.25;
    t.q(i, kAnkleFlexion) = a_f;
    const LegPoses P = leg_poses(leg, t.q.row(i).transpose());
    const Eigen::Vector3d ankle = P.X_WC.translation();
    t.grf_force_W.row(i) = F.transpose();
    t.grf_cop_W.row(i) << ankle.x() + d, 0.0, ankle.z() + e;
    t.grf_torque_W.row(i) << 0.0, 1.5, 0.0;
  }
  const KneeLoads k = compute_knee_loads(t, leg);
  const double ms = leg.shank.mass_kg, mf = leg.foot.mass_kg;
  EXPECT_NEAR(ms, 0.0465 * 61.0, 1e-12);
  EXPECT_NEAR(mf, 0.0145 * 61.0, 1e-12);
  // Knee above the ankle by L_s; COP on the floor (y = 0), so the vertical arm
  // is the ankle height above the floor plus L_s.
  const LegPoses P = leg_poses(leg, t.q.row(0).transpose());
  const double ankle_y = P.X_WC.translation().y();
  const Eigen::Vector3d r(d, -(leg.shank_length_m + ankle_y), e);
  const double x_f = (Eigen::AngleAxisd(a_f, Eigen::Vector3d::UnitZ()) * leg.foot.p_com).x();
  const Eigen::Vector3d F_exp = F - (ms + mf) * kG * Eigen::Vector3d::UnitY();
  const Eigen::Vector3d M_exp = r.cross(F) + Eigen::Vector3d(0, 1.5, 0) +
                                Eigen::Vector3d(0, 0, -x_f * mf * kG);
  for (int i = 0; i < 4; ++i) {
    EXPECT_LT((k.F_ext_T.row(i).transpose() - F_exp).norm(), 1e-9);
    EXPECT_LT((k.M_ext_T.row(i).transpose() - M_exp).norm(), 1e-9);
  }
  // The shank is vertical, so the tibia frame is the world frame.
  EXPECT_LT((k.X_WT[0].linear() - Eigen::Matrix3d::Identity()).norm(), 1e-12);
  // The foot alone about the ankle (the ankle row of COMAK): r_a = COP -
  // ankle = (d, -h_a, e), F_foot = F - m_f g e_y, M_foot = r_a x F + T_free
  // + (0, 0, -x_f m_f g) (x_f is also the foot COM's offset from the ankle).
  ASSERT_TRUE(k.has_foot_loads);
  EXPECT_EQ(k.ankle_centre_T, Eigen::Vector3d(0, -leg.shank_length_m, 0));
  const Eigen::Vector3d r_a(d, -ankle_y, e);
  const Eigen::Vector3d F_foot = F - mf * kG * Eigen::Vector3d::UnitY();
  const Eigen::Vector3d M_foot = r_a.cross(F) + Eigen::Vector3d(0, 1.5, 0) +
                                 Eigen::Vector3d(0, 0, -x_f * mf * kG);
  for (int i = 0; i < 4; ++i) {
    EXPECT_LT((k.F_foot_T.row(i).transpose() - F_foot).norm(), 1e-9);
    EXPECT_LT((k.M_foot_T.row(i).transpose() - M_foot).norm(), 1e-9);
  }
}

// Swing, no ground reaction: shank and foot (ankle fixed) swing as one
// pendulum about the knee's Z axis, phi = hip - knee, knee = 0.6 + 0.5 sin(2 pi t).
// COM i at d_i = Rz(phi) r_i from the knee: a_i = phi'' z x d_i + phi'^2 z x (z x d_i);
// F_ext = sum m_i (g - a_i), M_ext = sum d_i x m_i (g - a_i) - (Izz_s + Izz_f) phi'' z.
// The implementation differentiates poses numerically along the Taylor path
// (step 1e-4 s): truncation ~ (1e-4)^2/12 x phi'^4 x 0.5 m x 3.7 kg < 1e-6, rounding
// ~1e-16 / 1e-8 m/s^2 x 3.7 kg ~ 4e-8: tolerance 1e-5 N, N m.
TEST(KneeLoads, SwingPendulumClosedForm) {
  const int n = 30;
  GaitTrial t = empty_trial(n);
  const LegModel leg = leg_model_from_anthropometry(61.0, 1.65);
  const double hip = 0.3, ankle = 0.1, w = 2 * M_PI;
  for (int i = 0; i < n; ++i) {
    const double s = t.time(i);
    t.q(i, kPelvisTy) = 0.9;
    t.q(i, kPelvisTilt) = 0.0;
    t.q(i, kHipFlexion) = hip;
    t.q(i, kAnkleFlexion) = ankle;
    t.q(i, kKneeFlexion) = 0.6 + 0.5 * std::sin(w * s);
    t.qd(i, kKneeFlexion) = 0.5 * w * std::cos(w * s);
    t.qdd(i, kKneeFlexion) = -0.5 * w * w * std::sin(w * s);
  }
  const KneeLoads k = compute_knee_loads(t, leg);
  const Eigen::Vector3d g(0, -kG, 0), z = Eigen::Vector3d::UnitZ();
  const Eigen::Vector3d r_s = leg.shank.p_com;
  const Eigen::Vector3d r_f = Eigen::Vector3d(0, -leg.shank_length_m, 0) +
                              Eigen::AngleAxisd(ankle, z) * leg.foot.p_com;
  const double Izz = leg.shank.inertia_about_com()(2, 2) + leg.foot.inertia_about_com()(2, 2);
  double worst_f = 0, worst_m = 0;
  for (int i = 0; i < n; ++i) {
    const double phi = hip - t.q(i, kKneeFlexion), phid = -t.qd(i, kKneeFlexion),
                 phidd = -t.qdd(i, kKneeFlexion);
    const Eigen::Matrix3d R = Eigen::AngleAxisd(phi, z).toRotationMatrix();
    Eigen::Vector3d F = Eigen::Vector3d::Zero(), M = Eigen::Vector3d::Zero();
    for (auto [m, r] : {std::pair{leg.shank.mass_kg, r_s}, std::pair{leg.foot.mass_kg, r_f}}) {
      const Eigen::Vector3d d = R * r;
      const Eigen::Vector3d a = phidd * z.cross(d) + phid * phid * z.cross(z.cross(d));
      F += m * (g - a);
      M += d.cross(m * (g - a));
    }
    M -= Izz * phidd * z;
    const Eigen::Vector3d F_T = R.transpose() * F, M_T = R.transpose() * M;
    worst_f = std::max(worst_f, (k.F_ext_T.row(i).transpose() - F_T).norm());
    worst_m = std::max(worst_m, (k.M_ext_T.row(i).transpose() - M_T).norm());
  }
  EXPECT_LT(worst_f, 1e-5);
  EXPECT_LT(worst_m, 1e-5);
  // Quasi-static option: only the weights remain.
  KneeLoadOptions qs;
  qs.include_inertia = false;
  const KneeLoads k0 = compute_knee_loads(t, leg, qs);
  const Eigen::Vector3d W_W = (leg.shank.mass_kg + leg.foot.mass_kg) * g;
  const Eigen::Vector3d W_T = k0.X_WT[7].linear().transpose() * W_W;
  EXPECT_LT((k0.F_ext_T.row(7).transpose() - W_T).norm(), 1e-9);
}

// A general moving trial (all coordinates move, ground reaction present).
GaitTrial moving_trial(int n) {
  GaitTrial t = empty_trial(n);
  for (int i = 0; i < n; ++i) {
    const double s = t.time(i);
    for (int c = 0; c < kNumTrialCoordinates; ++c) {
      const double amp = (c >= kPelvisTx && c <= kPelvisTz) ? 0.05 : 0.2;
      const double w = 2.0 + 0.7 * c, ph = 0.3 * c;
      const double base = c == kPelvisTy ? 0.92 : (c == kPelvisTx ? 1.2 * s : 0.1 * (c % 3));
      t.q(i, c) = base + amp * std::sin(w * s + ph);
      t.qd(i, c) = (c == kPelvisTx ? 1.2 : 0.0) + amp * w * std::cos(w * s + ph);
      t.qdd(i, c) = -amp * w * w * std::sin(w * s + ph);
    }
    t.grf_force_W.row(i) << 50.0 * std::sin(3 * s), 500.0 + 80 * std::cos(2 * s), -20.0 + 5 * s;
    t.grf_cop_W.row(i) << 1.2 * s + 0.1, 0.0, 0.05;
    t.grf_torque_W.row(i) << 0.0, 2.0 * std::sin(4 * s), 0.0;
  }
  return t;
}

// Frame invariance: turning the whole lab about the vertical by beta (walking in
// another direction) leaves the loads in the tibia frame unchanged. With pelvis
// tilt and list zero, R_WP = Ry(rotation), so the turn adds beta to
// pelvis_rotation; pelvis translation and ground reactions are rotated.
// Rounding plus finite-difference error of the same order in both runs: 1e-6.
TEST(KneeLoads, InvariantToWalkingDirection) {
  GaitTrial a = moving_trial(12);
  for (auto* m : {&a.q, &a.qd, &a.qdd}) {
    m->col(kPelvisTilt).setZero();
    m->col(kPelvisList).setZero();
  }
  const LegModel leg = leg_model_from_anthropometry(61.0, 1.65);
  const double beta = 0.7;
  const Eigen::Matrix3d Ry = Eigen::AngleAxisd(beta, Eigen::Vector3d::UnitY()).toRotationMatrix();
  GaitTrial b = a;
  b.q.col(kPelvisRotation).array() += beta;
  for (auto [src, dst] : {std::pair{&a.q, &b.q}, std::pair{&a.qd, &b.qd}, std::pair{&a.qdd, &b.qdd}}) {
    for (int i = 0; i < a.num_samples(); ++i) {
      dst->row(i).segment(kPelvisTx, 3) = (Ry * src->row(i).segment(kPelvisTx, 3).transpose()).transpose();
    }
  }
  for (auto [src, dst] : {std::pair{&a.grf_force_W, &b.grf_force_W}, std::pair{&a.grf_cop_W, &b.grf_cop_W},
                          std::pair{&a.grf_torque_W, &b.grf_torque_W}}) {
    *dst = (*src) * Ry.transpose();
  }
  const KneeLoads ka = compute_knee_loads(a, leg), kb = compute_knee_loads(b, leg);
  EXPECT_LT((ka.F_ext_T - kb.F_ext_T).cwiseAbs().maxCoeff(), 1e-6);
  EXPECT_LT((ka.M_ext_T - kb.M_ext_T).cwiseAbs().maxCoeff(), 1e-6);
  EXPECT_GT(ka.M_ext_T.cwiseAbs().maxCoeff(), 1.0);  // a non-trivial case
}

// A left leg that is the mirror image of a right one (z -> -z) has mirrored
// loads: forces (x, y, -z), moments (-x, -y, z) in the tibia frames.
TEST(KneeLoads, LeftLegIsMirrorOfRight) {
  const GaitTrial r = moving_trial(10);
  GaitTrial l = r;
  l.side = Side::kLeft;
  for (auto* m : {&l.q, &l.qd, &l.qdd}) {
    m->col(kPelvisList) *= -1;
    m->col(kPelvisRotation) *= -1;
    m->col(kPelvisTz) *= -1;
  }
  l.grf_force_W.col(2) *= -1;
  l.grf_cop_W.col(2) *= -1;
  l.grf_torque_W.col(0) *= -1;
  l.grf_torque_W.col(1) *= -1;
  const LegModel leg = leg_model_from_anthropometry(61.0, 1.65);
  const KneeLoads kr = compute_knee_loads(r, leg), kl = compute_knee_loads(l, leg);
  const Eigen::RowVector3d fp(1, 1, -1), ax(-1, -1, 1);
  for (int i = 0; i < r.num_samples(); ++i) {
    EXPECT_LT((kl.F_ext_T.row(i) - kr.F_ext_T.row(i).cwiseProduct(fp)).norm(), 1e-9);
    EXPECT_LT((kl.M_ext_T.row(i) - kr.M_ext_T.row(i).cwiseProduct(ax)).norm(), 1e-9);
    EXPECT_LT((kl.F_foot_T.row(i) - kr.F_foot_T.row(i).cwiseProduct(fp)).norm(), 1e-9);
    EXPECT_LT((kl.M_foot_T.row(i) - kr.M_foot_T.row(i).cwiseProduct(ax)).norm(), 1e-9);
    // The left knee lies on the other side of the sagittal plane.
    EXPECT_NEAR(kl.X_WT[i].translation().z(), -kr.X_WT[i].translation().z(), 1e-12);
  }
}

TEST(KneeLoads, GivenLoadsPassThroughAndMissingInputsAreErrors) {
  GaitTrial t = empty_trial(5);
  t.has_knee_loads = true;
  t.knee_force_T = Eigen::MatrixXd::Constant(5, 3, 7.0);
  t.knee_moment_T = Eigen::MatrixXd::Constant(5, 3, -2.0);
  const LegModel leg = leg_model_from_anthropometry(61.0, 1.65);
  const KneeLoads k = compute_knee_loads(t, leg);
  EXPECT_EQ(k.source, KneeLoadSource::kGivenByTrial);
  EXPECT_EQ(k.F_ext_T, t.knee_force_T);
  EXPECT_EQ(k.M_ext_T, t.knee_moment_T);
  EXPECT_FALSE(k.has_foot_loads);  // no foot inverse dynamics: no ankle row possible
  GaitTrial u = empty_trial(5);
  u.has_pelvis = false;
  EXPECT_THROW(compute_knee_loads(u, leg), common::InputError);
  GaitTrial v = empty_trial(5);
  v.q(2, kKneeFlexion) = std::nan("");
  EXPECT_THROW(compute_knee_loads(v, leg), common::NumericalError);
}

}  // namespace
}  // namespace arthrosim::musculoskeletal
