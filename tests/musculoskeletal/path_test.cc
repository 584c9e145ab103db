// Paths over a kinematic tree: cylinder wrap length vs closed form, moment
// arms r = -dl/dq from the force applications vs central finite differences of
// the length, equal and opposite forces, point Jacobian vs finite differences.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <random>
#include <numbers>

#include "common/error.h"
#include "musculoskeletal/kinematics.h"
#include "musculoskeletal/model.h"
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
  return msk::evaluate_path(path, d.X_WB, q).length;
}

// -dl/dq from the applications (unit tension).
Eigen::VectorXd moment_arms(const msk::KinematicTree& t, const msk::Path& path,
                            const Eigen::VectorXd& q, msk::PathState* out = nullptr) {
  msk::KinematicsData d;
  msk::forward_kinematics(t, q, d);
  auto st = msk::evaluate_path(path, d.X_WB, q);
  Eigen::VectorXd Q = Eigen::VectorXd::Zero(t.num_coordinates());
  for (const auto& a : st.applications) msk::add_point_force(t, d, a.body, a.point_W, a.direction_W, Q);
  for (const auto& f : st.coordinate_forces) Q[f.coordinate] += f.force;
  if (out) *out = st;
  return Q;
}

double expect_moment_arms_match_fd(const msk::KinematicTree& t, const msk::Path& path,
                                   const Eigen::VectorXd& q, double tol = 1e-8) {
  double worst = 0.0;
  const Eigen::VectorXd r = moment_arms(t, path, q);
  const double h = 1e-6;
  for (int i = 0; i < t.num_coordinates(); ++i) {
    Eigen::VectorXd qp = q, qm = q;
    qp[i] += h;
    qm[i] -= h;
    const double fd = -(length_at(t, path, qp) - length_at(t, path, qm)) / (2 * h);
    // Central difference: truncation ~h^2 l''' ~ 1e-12 m, round-off ~1e-16 * 0.1 / 1e-6 = 1e-11:
    // 1e-8 (m per rad or m per m) is far below any real moment arm (~1e-2 m).
    EXPECT_NEAR(r[i], fd, tol) << "coordinate " << t.coordinates[i];
    worst = std::max(worst, std::abs(r[i] - fd));
  }
  return worst;
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

namespace {

// World positions of the femur point and the tibia point of a two-point
// path at q.
std::pair<Vec3, Vec3> ends_W(const msk::KinematicTree& t, const msk::Path& path, const Eigen::VectorXd& q) {
  msk::KinematicsData d;
  msk::forward_kinematics(t, q, d);
  return {d.X_WB[path.points.front().body] * path.points.front().p_B,
          d.X_WB[path.points.back().body] * path.points.back().p_B};
}

// Places surface frame S on `body` so that, at q, its origin lies `offset`
// from the midpoint of the segment a-b (along a direction normal to it) and
// its axis `axis_S` (local) points along `axis_W`.
msk::Pose place(const msk::KinematicTree& t, int body, const Eigen::VectorXd& q, const Vec3& origin_W,
                const Eigen::Matrix3d& R_WS) {
  msk::KinematicsData d;
  msk::forward_kinematics(t, q, d);
  msk::Pose X_WS = msk::Pose::Identity();
  X_WS.linear() = R_WS;
  X_WS.translation() = origin_W;
  return d.X_WB[body].inverse() * X_WS;
}

// A rotation whose columns are e1, e2, e1 x e2 (e1, e2 orthonormalised).
Eigen::Matrix3d frame(const Vec3& e1, const Vec3& e2_hint) {
  const Vec3 x = e1.normalized();
  const Vec3 y = (e2_hint - e2_hint.dot(x) * x).normalized();
  Eigen::Matrix3d R;
  R.col(0) = x;
  R.col(1) = y;
  R.col(2) = x.cross(y);
  return R;
}

msk::Path femur_to_tibia(const msk::KinematicTree& t) {
  msk::Path path;
  path.points = {{0, Vec3(0.003, 0.06, 0.004)}, {t.body_index("tibia"), Vec3(-0.004, -0.055, 0.002)}};
  return path;
}

}  // namespace

TEST(Path, WrappedMomentArmsMatchFiniteDifferencesForEveryShape) {
  // Femur origin, tibia insertion, the surface on the patella (a third body
  // on its own chain), placed so that the straight line at q cuts it; then
  // r = -dl/dq from the applications against central differences of l over
  // all 12 coordinates.
  auto t = make_tree();
  const int pat = t.body_index("patella");
  const Eigen::VectorXd q = some_q(12, 0.05);
  const msk::Path base = femur_to_tibia(t);
  const auto [P, S] = ends_W(t, base, q);
  const Vec3 dir = (S - P).normalized(), mid = 0.5 * (P + S);
  const Vec3 nrm = dir.cross(Vec3(0.3, 0.2, 1.0)).normalized();  // normal to the segment
  struct Case {
    const char* name;
    msk::WrapSurface s;
    double tol;
  };
  std::vector<Case> cases;
  {
    msk::WrapSurface c;  // finite cylinder, quadrant +x: axis normal to the line
    c.name = "cylinder";
    c.body = pat;
    c.radius = 0.02;
    c.length = 0.08;
    c.quadrant = msk::WrapQuadrant::kPosX;
    // The line passes 3 mm from the axis on the -nrm side; local x = -nrm,
    // so +x is the side of the line (the short way round).
    const Vec3 axis = dir.cross(nrm).normalized();
    Eigen::Matrix3d Rc;
    Rc.col(0) = -nrm;
    Rc.col(2) = axis;
    Rc.col(1) = axis.cross(-nrm);
    c.X_BS = place(t, pat, q, mid + 0.003 * nrm, Rc);
    cases.push_back({"cylinder +x, finite", c, 1e-8});
    msk::WrapSurface sp;
    sp.name = "sphere";
    sp.shape = msk::WrapShape::kSphere;
    sp.body = pat;
    sp.radius = 0.02;
    sp.X_BS = place(t, pat, q, mid + 0.003 * nrm, Eigen::Matrix3d::Identity());
    cases.push_back({"sphere", sp, 1e-8});
    msk::WrapSurface e;
    e.name = "ellipsoid";
    e.shape = msk::WrapShape::kEllipsoid;
    e.body = pat;
    e.semi_axes = Vec3(0.025, 0.018, 0.04);
    e.X_BS = place(t, pat, q, mid + 0.003 * nrm, frame(Vec3(0.4, 1.0, 0.2), Vec3(1.0, 0.1, -0.3)));
    cases.push_back({"ellipsoid", e, 1e-8});
    msk::WrapSurface to;
    to.name = "torus";
    to.shape = msk::WrapShape::kTorus;
    to.body = pat;
    to.radius = 0.012;
    to.ring_radius = 0.03;
    // Torus axis (local z) about the line direction, tilted; the line passes
    // 0.027 m from the axis, 9 mm into the tube (inner equator at 0.018 m).
    Eigen::Matrix3d Rt;
    Rt.col(2) = (dir + 0.15 * nrm.cross(dir)).normalized();
    Rt.col(0) = (nrm - nrm.dot(Rt.col(2)) * Rt.col(2)).normalized();
    Rt.col(1) = Rt.col(2).cross(Rt.col(0));
    to.X_BS = place(t, pat, q, mid - 0.027 * nrm, Rt);
    cases.push_back({"torus", to, 1e-8});
  }
  for (const Case& c : cases) {
    msk::Path path = base;
    path.wraps = {msk::PathWrap{c.s}};
    msk::PathState st;
    moment_arms(t, path, q, &st);
    ASSERT_TRUE(st.wrapped) << c.name << ": test geometry must wrap";
    EXPECT_GT(st.contacts[0].arc_length, 0.004) << c.name;
    const double worst = expect_moment_arms_match_fd(t, path, q, c.tol);
    std::printf("%-20s l = %.9f m, arc %.4f m, max |r - FD| = %.1e\n", c.name, st.length,
                st.contacts[0].arc_length, worst);
    // Tolerance 1e-8 m/rad as for straight paths (central differences with
    // h = 1e-6: truncation ~h^2 d3l/dq3 ~ 1e-12 m, round-off ~1e-16 x 0.1 m /
    // 1e-6 = 1e-11 m); measured 7e-11 .. 5e-9 (sphere).
    // A closed system: the net force per unit tension is zero.
    Vec3 net = Vec3::Zero();
    for (const auto& a : st.applications) net += a.direction_W;
    EXPECT_LT(net.norm(), 1e-13) << c.name;
  }
}

namespace {

// A sphere of radius R on `body` centred `offset` from the midpoint of the
// world segment a-b (along n).
msk::WrapSurface sphere_near(const msk::KinematicTree& t, int body, const Eigen::VectorXd& q, const Vec3& a,
                             const Vec3& b, const Vec3& n, double R, double offset) {
  msk::WrapSurface s;
  s.name = "sphere";
  s.shape = msk::WrapShape::kSphere;
  s.body = body;
  s.radius = R;
  s.X_BS = place(t, body, q, 0.5 * (a + b) + offset * n, Eigen::Matrix3d::Identity());
  return s;
}

}  // namespace

TEST(Path, WrapRangesSelectTheSegmentAndChainsOfWrapsAreStationary) {
  auto t = make_tree();
  const int pat = t.body_index("patella"), tib = t.body_index("tibia");
  const Eigen::VectorXd q = some_q(12, 0.05);
  msk::Path path;
  path.points = {{0, Vec3(0.0, 0.1, 0.0)}, {0, Vec3(0.01, 0.05, 0.0)}, {pat, Vec3(0.0, 0.0, 0.0)},
                 {tib, Vec3(0.0, -0.06, 0.005)}};
  msk::KinematicsData d;
  msk::forward_kinematics(t, q, d);
  const Vec3 p2 = d.X_WB[pat] * path.points[2].p_B, p3 = d.X_WB[tib] * path.points[3].p_B;
  const Vec3 n = (p3 - p2).cross(Vec3(0, 0, 1)).normalized();
  // A sphere cutting segment 3-4 (1-based); range "1 2" excludes it.
  msk::PathWrap w{sphere_near(t, tib, q, p2, p3, n, 0.012, 0.004)};
  w.first_point = 0;
  w.last_point = 1;
  path.wraps = {w};
  EXPECT_FALSE(msk::evaluate_path(path, d.X_WB).wrapped);
  path.wraps[0].first_point = 2;  // "3 4"
  path.wraps[0].last_point = 3;
  msk::PathState st = msk::evaluate_path(path, d.X_WB);
  ASSERT_TRUE(st.wrapped);
  EXPECT_EQ(st.contacts.size(), 1u);
  expect_moment_arms_match_fd(t, path, q);
  // Whole-path range (-1 -1) finds the same segment.
  path.wraps[0].first_point = path.wraps[0].last_point = -1;
  EXPECT_EQ(msk::evaluate_path(path, d.X_WB).length, st.length);
  // A second sphere on the patella further along the same segment: the two
  // wraps share the segment and their contact points are refined together;
  // the chain must be stationary (moment arms = -dl/dq).
  msk::WrapSurface s2 = sphere_near(t, pat, q, p2, p3, n, 0.012, 0.0);
  s2.X_BS = place(t, pat, q, p2 + 0.25 * (p3 - p2) + 0.004 * n, Eigen::Matrix3d::Identity());
  s2.name = "second";
  path.wraps.push_back(msk::PathWrap{s2});
  st = msk::evaluate_path(path, d.X_WB);
  ASSERT_EQ(st.contacts.size(), 2u) << "both wraps must be active";
  const double worst = expect_moment_arms_match_fd(t, path, q);
  std::printf("two spheres on one segment: l = %.9f m, max |r - FD| = %.1e\n", st.length, worst);
}

TEST(Path, ConditionalAndMovingPoints) {
  auto t = make_tree();
  const int tib = t.body_index("tibia"), pat = t.body_index("patella");
  const int c_tf = t.coordinate_index("tf0"), c_pf = t.coordinate_index("pf1");
  msk::Path path;
  path.points.push_back({0, Vec3(0.0, 0.08, 0.0)});
  msk::PathPoint cond(0, Vec3(0.02, 0.02, 0.0));
  cond.condition_coordinate = c_tf;
  cond.range_min = -1.0;
  cond.range_max = 0.0;
  path.points.push_back(cond);
  // A moving point on the tibia: x, y follow the tibia's own flexion tf0
  // (a spline and a linear function), z follows pf1, which does not move
  // the tibia (only the direct generalized force acts on it).
  msk::PathPoint mov(tib, Vec3::Zero());
  mov.moving_coordinate = {c_tf, c_tf, c_pf};
  mov.moving[0] = std::make_shared<const msk::CoordinateFunction>(
      msk::CoordinateFunction::cubic_spline({-1.0, -0.4, 0.0, 0.5, 1.0}, {0.01, 0.02, 0.025, 0.022, 0.015}));
  mov.moving[1] = std::make_shared<const msk::CoordinateFunction>(msk::CoordinateFunction::linear(0.01, -0.05));
  mov.moving[2] = std::make_shared<const msk::CoordinateFunction>(
      msk::CoordinateFunction::cubic_spline({-1.0, 0.0, 1.0}, {-0.01, 0.0, 0.02}).scaled(0.8));
  path.points.push_back(mov);
  path.points.push_back({pat, Vec3(0.0, -0.01, 0.0)});
  ASSERT_TRUE(msk::path_needs_coordinates(path));
  Eigen::VectorXd q = some_q(12, 0.2);
  q[c_tf] = -0.3;  // conditional point active
  msk::KinematicsData d;
  msk::forward_kinematics(t, q, d);
  msk::PathState st = msk::evaluate_path(path, d.X_WB, q);
  EXPECT_EQ(st.points_W.size(), 4u);
  ASSERT_FALSE(st.coordinate_forces.empty());
  expect_moment_arms_match_fd(t, path, q);
  q[c_tf] = 0.3;  // inactive
  msk::forward_kinematics(t, q, d);
  st = msk::evaluate_path(path, d.X_WB, q);
  EXPECT_EQ(st.points_W.size(), 3u);
  expect_moment_arms_match_fd(t, path, q);
  // The moving point sits where its functions put it.
  EXPECT_LT((st.points_W[1] - d.X_WB[tib] * Vec3(mov.moving[0]->value(0.3), mov.moving[1]->value(0.3),
                                                   mov.moving[2]->value(q[c_pf])))
                .norm(),
            1e-16);
  // q is required.
  EXPECT_THROW(msk::evaluate_path(path, d.X_WB), arthrosim::common::InputError);
  // Dependencies for the Jacobian's column skipping: pf1 moves neither the
  // femur nor the tibia, but the moving point depends on it.
  std::vector<char> none(t.bodies.size(), 0);
  EXPECT_TRUE(msk::path_depends_on(path, none, c_pf));
  EXPECT_TRUE(msk::path_depends_on(path, none, c_tf));
  EXPECT_FALSE(msk::path_depends_on(path, none, t.coordinate_index("pf0")));
}

TEST(Path, GeneralizedForcesThroughTheModelEqualMinusTensionTimesLengthGradient) {
  // A muscle with a moving point and an ellipsoid wrap in a Model:
  // Q_muscles = -a F_max dl/dq (central differences of l through the model's
  // kinematics), and dQ/dq is the same with and without skipping the columns
  // of coordinates that move none of the terms' bodies.
  msk::Model m;
  m.tree = make_tree();
  const int tib = m.tree.body_index("tibia"), pat = m.tree.body_index("patella");
  const Eigen::VectorXd q = some_q(12, 0.05);
  msk::Muscle mu;
  mu.name = "wrapped";
  mu.max_isometric_force = 800.0;
  mu.path = femur_to_tibia(m.tree);
  msk::PathPoint mov(pat, Vec3::Zero());
  mov.moving_coordinate = {m.tree.coordinate_index("tf2"), m.tree.coordinate_index("pf0"), m.tree.coordinate_index("pf0")};
  mov.moving[0] = std::make_shared<const msk::CoordinateFunction>(msk::CoordinateFunction::linear(0.01, 0.03));
  mov.moving[1] = std::make_shared<const msk::CoordinateFunction>(msk::CoordinateFunction::constant(-0.02));
  mov.moving[2] = std::make_shared<const msk::CoordinateFunction>(
      msk::CoordinateFunction::piecewise_linear({-1, 0, 1}, {0.0, 0.004, 0.001}));
  mu.path.points.insert(mu.path.points.begin() + 1, mov);
  {
    msk::KinematicsData d;
    msk::forward_kinematics(m.tree, q, d);
    const Vec3 a = d.X_WB[pat] * Vec3(0.03 + 0.01 * q[m.tree.coordinate_index("tf2")], -0.02, 0.004);
    const Vec3 b = d.X_WB[tib] * mu.path.points.back().p_B;
    msk::WrapSurface e;
    e.name = "ell";
    e.shape = msk::WrapShape::kEllipsoid;
    e.body = tib;
    e.semi_axes = Vec3(0.012, 0.015, 0.02);
    const Vec3 n = (b - a).cross(Vec3(0, 0, 1)).normalized();
    e.X_BS = place(m.tree, tib, q, 0.5 * (a + b) + 0.004 * n, frame(Vec3(1, 0.3, 0), Vec3(0, 1, 0.2)));
    mu.path.wraps = {msk::PathWrap{e}};
  }
  m.muscles.push_back(mu);
  for (int i = 0; i < m.num_coordinates(); ++i) m.free_coordinates.push_back(i);
  msk::ModelData d = msk::make_data(m);
  const Eigen::VectorXd a = Eigen::VectorXd::Constant(1, 0.5);
  msk::ForceOptions opt;
  opt.ligaments = opt.contact = false;
  msk::evaluate_forces(m, d, q, Eigen::VectorXd(), a, opt);
  ASSERT_TRUE(d.muscle_paths[0].wrapped);
  const double T = 0.5 * 800.0;
  for (int i = 0; i < m.num_coordinates(); ++i) {
    Eigen::VectorXd qp = q, qm = q;
    qp[i] += 1e-6;
    qm[i] -= 1e-6;
    msk::ModelData dp = msk::make_data(m), dm = msk::make_data(m);
    msk::evaluate_forces(m, dp, qp, Eigen::VectorXd(), a, opt);
    msk::evaluate_forces(m, dm, qm, Eigen::VectorXd(), a, opt);
    const double fd = -T * (dp.muscle_paths[0].length - dm.muscle_paths[0].length) / 2e-6;
    // 400 N x the 1e-8 m/rad moment-arm tolerance.
    EXPECT_NEAR(d.Q_muscles[i], fd, 4e-6) << m.tree.coordinates[i];
  }
  msk::ModelData j1 = msk::make_data(m), j2 = msk::make_data(m);
  msk::evaluate_jacobian(m, j1, q, Eigen::VectorXd(), a, opt);
  opt.jacobian_skip_unmoved_terms = false;
  msk::evaluate_jacobian(m, j2, q, Eigen::VectorXd(), a, opt);
  EXPECT_LT((j1.dQ_dq - j2.dQ_dq).cwiseAbs().maxCoeff(), 1e-9 * j2.dQ_dq.cwiseAbs().maxCoeff());
}

TEST(Path, LengthIsFrameInvariant) {
  // The same wrapped path (ellipsoid, cylinder, sphere on one segment each)
  // with the root placed at random world poses: same length to rounding.
  auto t = make_tree();
  const int pat = t.body_index("patella"), tib = t.body_index("tibia");
  const Eigen::VectorXd q = some_q(12, 0.05);
  msk::Path path = femur_to_tibia(t);
  const auto [P, S] = ends_W(t, path, q);
  const Vec3 n = (S - P).cross(Vec3(0.2, 0.1, 1)).normalized();
  msk::WrapSurface e;
  e.name = "ell";
  e.shape = msk::WrapShape::kEllipsoid;
  e.body = pat;
  e.semi_axes = Vec3(0.02, 0.014, 0.03);
  e.X_BS = place(t, pat, q, 0.5 * (P + S) + 0.005 * n, frame(Vec3(0.2, 1, 0.4), Vec3(1, 0, 0)));
  path.wraps = {msk::PathWrap{e}};
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> U(-1, 1);
  double ref = 0;
  for (int k = 0; k < 6; ++k) {
    msk::Pose X_W0 = msk::Pose::Identity();
    if (k > 0) {
      X_W0.linear() = Eigen::AngleAxisd(3 * U(rng), Vec3(U(rng), U(rng), U(rng)).normalized()).toRotationMatrix();
      X_W0.translation() = Vec3(U(rng), U(rng), U(rng));
    }
    msk::KinematicsData d;
    msk::forward_kinematics(t, q, d, X_W0);
    const msk::PathState st = msk::evaluate_path(path, d.X_WB);
    ASSERT_TRUE(st.wrapped);
    if (k == 0) ref = st.length;
    // Poses ~1 m from the origin: coordinates carry ~1e-16 m rounding; the
    // length is stationary in the contact points, so they do not matter.
    EXPECT_NEAR(st.length, ref, 1e-14) << k;
  }
  (void)tib;
}

TEST(Path, StraightPathLengthIsTheOrderedSumOfSegments) {
  // Straight paths keep the arithmetic of the earlier two-point code (sum of
  // |x_{k+1} - x_k| in order): bit-identical results for models without wraps.
  auto t = make_tree();
  msk::Path path;
  path.points = {{0, Vec3(0.02, 0.1, 0.01)}, {0, Vec3(0.04, 0.01, 0.0)},
                 {t.body_index("tibia"), Vec3(0.03, -0.06, 0.0)}};
  msk::KinematicsData d;
  msk::forward_kinematics(t, some_q(12, 0.3), d);
  const msk::PathState st = msk::evaluate_path(path, d.X_WB);
  double l = 0.0;
  for (size_t i = 0; i + 1 < st.points_W.size(); ++i) l += (st.points_W[i + 1] - st.points_W[i]).norm();
  EXPECT_EQ(st.length, l);
  EXPECT_EQ(st.applications.size(), 4u);
}
