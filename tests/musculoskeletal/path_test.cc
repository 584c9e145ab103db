// Paths over a kinematic tree: cylinder wrap length vs closed form, moment
// arms r = -dl/dq from the force applications vs central finite differences of
// the length, equal and opposite forces, point Jacobian vs finite differences.
#include <gtest/gtest.h>

#include <cmath>
#include <numbers>

#include "musculoskeletal/kinematics.h"
#include "musculoskeletal/path.h"

namespace msk = arthrosim::musculoskeletal;
using msk::Vec3;

namespace {

// Root body 0 ("femur") and body 1 ("tibia") on a 6-DOF chain (3 revolute,
// 3 prismatic), body 2 ("patella") on another 6-DOF chain from the root.
msk::KinematicTree make_tree() {
  msk::KinematicTree t;
  t.add_root("femur", 1.0);
  auto chain = [&](const std::string& prefix, const std::string& end, Vec3 offset) {
    int parent = 0;
    const Vec3 axes[6] = {Vec3::UnitZ(), Vec3::UnitX(), Vec3::UnitY(),
                          Vec3::UnitX(), Vec3::UnitY(), Vec3::UnitZ()};
    for (int i = 0; i < 6; ++i) {
      msk::Joint j;
      j.name = prefix + std::to_string(i);
      j.type = i < 3 ? msk::JointType::kRevolute : msk::JointType::kPrismatic;
      j.parent = parent;
      j.axis_J = axes[i];
      if (i == 0) j.X_PJ.translation() = offset;
      parent = t.add_body(i == 5 ? end : prefix + "_link" + std::to_string(i), 0.0, j);
    }
    return parent;
  };
  chain("tf", "tibia", Vec3(0.001, -0.002, 0.0005));
  chain("pf", "patella", Vec3(0.03, 0.01, 0.0));
  return t;
}

Eigen::VectorXd some_q(int n, double scale) {
  Eigen::VectorXd q(n);
  for (int i = 0; i < n; ++i) q[i] = scale * std::sin(1.7 * i + 0.3);
  return q;
}

double length_at(const msk::KinematicTree& t, const msk::Path& path, const Eigen::VectorXd& q) {
  msk::KinematicsData d;
  msk::forward_kinematics(t, q, d);
  return msk::evaluate_path(path, d.X_WB).length;
}

// -dl/dq from the applications (unit tension).
Eigen::VectorXd moment_arms(const msk::KinematicTree& t, const msk::Path& path,
                            const Eigen::VectorXd& q, msk::PathState* out = nullptr) {
  msk::KinematicsData d;
  msk::forward_kinematics(t, q, d);
  auto st = msk::evaluate_path(path, d.X_WB);
  Eigen::VectorXd Q = Eigen::VectorXd::Zero(t.num_coordinates());
  for (const auto& a : st.applications) msk::add_point_force(t, d, a.body, a.point_W, a.direction_W, Q);
  if (out) *out = st;
  return Q;
}

void expect_moment_arms_match_fd(const msk::KinematicTree& t, const msk::Path& path,
                                 const Eigen::VectorXd& q) {
  const Eigen::VectorXd r = moment_arms(t, path, q);
  const double h = 1e-6;
  for (int i = 0; i < t.num_coordinates(); ++i) {
    Eigen::VectorXd qp = q, qm = q;
    qp[i] += h;
    qm[i] -= h;
    const double fd = -(length_at(t, path, qp) - length_at(t, path, qm)) / (2 * h);
    // Central difference: truncation ~h^2 l''' ~ 1e-12 m, round-off ~1e-16 * 0.1 / 1e-6 = 1e-11:
    // 1e-8 (m per rad or m per m) is far below any real moment arm (~1e-2 m).
    EXPECT_NEAR(r[i], fd, 1e-8) << "coordinate " << t.coordinates[i];
  }
}

}  // namespace

TEST(Kinematics, PointJacobianMatchesFiniteDifferences) {
  auto t = make_tree();
  const Eigen::VectorXd q = some_q(t.num_coordinates(), 0.2);
  msk::KinematicsData d;
  msk::forward_kinematics(t, q, d);
  const int tib = t.body_index("tibia");
  const Vec3 p_B(0.01, -0.04, 0.02);
  const auto J = msk::point_jacobian(t, d, tib, d.X_WB[tib] * p_B);
  for (int i = 0; i < t.num_coordinates(); ++i) {
    Eigen::VectorXd qp = q, qm = q;
    qp[i] += 1e-6;
    qm[i] -= 1e-6;
    msk::KinematicsData dp, dm;
    msk::forward_kinematics(t, qp, dp);
    msk::forward_kinematics(t, qm, dm);
    const Vec3 fd = (dp.X_WB[tib] * p_B - dm.X_WB[tib] * p_B) / 2e-6;
    EXPECT_LT((J.col(i) - fd).norm(), 1e-8);  // central FD error ~1e-12
  }
}

TEST(Path, StraightMultiPointMomentArmsMatchFiniteDifferences) {
  auto t = make_tree();
  msk::Path path;
  path.points = {{0, Vec3(0.02, 0.1, 0.01)},
                 {0, Vec3(0.04, 0.01, 0.0)},
                 {t.body_index("patella"), Vec3(0.005, 0.01, 0.0)},
                 {t.body_index("patella"), Vec3(0.004, -0.02, 0.0)},
                 {t.body_index("tibia"), Vec3(0.03, -0.06, 0.0)}};
  for (double s : {0.0, 0.15, 0.4}) expect_moment_arms_match_fd(t, path, some_q(12, s));
}

TEST(Path, ForcesAreEqualAndOppositeAndOnTheLine) {
  auto t = make_tree();
  msk::Path path;
  path.points = {{0, Vec3(0.02, 0.1, 0.01)}, {t.body_index("tibia"), Vec3(0.03, -0.06, 0.0)}};
  msk::PathState st;
  moment_arms(t, path, some_q(12, 0.3), &st);
  ASSERT_EQ(st.applications.size(), 2u);
  const auto& a = st.applications[0];
  const auto& b = st.applications[1];
  EXPECT_LT((a.direction_W + b.direction_W).norm(), 1e-15);
  // Both forces lie along the line joining the two points (no net moment).
  EXPECT_LT(a.direction_W.cross(b.point_W - a.point_W).norm(), 1e-15);
  EXPECT_NEAR(a.direction_W.norm(), 1.0, 1e-15);
}

TEST(Path, CylinderWrapLengthMatchesClosedForm) {
  // Cylinder of radius R on the root, axis z; P at (rho, 0, 0), S at angle phi
  // and height dz: l = sqrt((2 sqrt(rho^2 - R^2) + R (phi - 2 acos(R/rho)))^2 + dz^2).
  msk::KinematicTree t;
  t.add_root("ground", 0.0);
  const double R = 0.01, rho = 0.03, phi = 3.0, dz = 0.015;
  msk::Path path;
  path.points = {{0, Vec3(rho, 0, 0)}, {0, Vec3(rho * std::cos(phi), rho * std::sin(phi), dz)}};
  msk::PathWrap c;
  c.surface.body = 0;
  c.surface.radius = R;
  path.wraps = {c};
  msk::KinematicsData d;
  msk::forward_kinematics(t, Eigen::VectorXd(0), d);
  const auto st = msk::evaluate_path(path, d.X_WB);
  const double Lxy = 2 * std::sqrt(rho * rho - R * R) + R * (phi - 2 * std::acos(R / rho));
  ASSERT_TRUE(st.wrapped);
  EXPECT_NEAR(st.length, std::hypot(Lxy, dz), 1e-15);
  // Same for the mirrored sense of travel (S at -phi).
  path.points[1].p_B = Vec3(rho * std::cos(phi), -rho * std::sin(phi), dz);
  EXPECT_NEAR(msk::evaluate_path(path, d.X_WB).length, std::hypot(Lxy, dz), 1e-15);
  // A straight line clear of the cylinder is not wrapped.
  path.points[1].p_B = Vec3(rho * std::cos(0.5), rho * std::sin(0.5), dz);
  const auto st2 = msk::evaluate_path(path, d.X_WB);
  EXPECT_FALSE(st2.wrapped);
  EXPECT_NEAR(st2.length, (path.points[1].p_B - path.points[0].p_B).norm(), 1e-15);
}

TEST(Path, WrappedMomentArmsMatchFiniteDifferencesWithCylinderOnAThirdBody) {
  auto t = make_tree();
  msk::Path path;
  // Femur origin, tibia insertion, cylinder on the patella chain body so all
  // three bodies carry forces.
  path.points = {{0, Vec3(0.0, 0.05, 0.0)}, {t.body_index("tibia"), Vec3(0.0, -0.05, 0.0)}};
  msk::WrapSurface c;
  c.body = t.body_index("patella");
  c.radius = 0.008;
  const Eigen::VectorXd q = some_q(12, 0.05);
  {
    // Put the axis (world z) 2 mm from the straight line at this q.
    msk::KinematicsData d;
    msk::forward_kinematics(t, q, d);
    msk::Pose X_WC = msk::Pose::Identity();
    const Vec3 P = d.X_WB[0] * path.points[0].p_B;
    const Vec3 S = d.X_WB[t.body_index("tibia")] * path.points[1].p_B;
    const Vec3 dir = (S - P).normalized();
    const Vec3 perp = Vec3::UnitZ().cross(dir).normalized();
    X_WC.translation() = 0.5 * (P + S) + 0.002 * perp;
    c.X_BS = d.X_WB[c.body].inverse() * X_WC;
  }
  path.wraps = {msk::PathWrap{c}};
  msk::PathState st;
  moment_arms(t, path, q, &st);
  ASSERT_TRUE(st.wrapped) << "test geometry must wrap";
  EXPECT_GT(st.wrap_arc_angle, 0.05);
  expect_moment_arms_match_fd(t, path, q);
  // Net force of a closed system is zero: sum of all applied directions.
  Vec3 net = Vec3::Zero();
  for (const auto& a : st.applications) net += a.direction_W;
  EXPECT_LT(net.norm(), 1e-14);
}
