#include "musculoskeletal/kinematics.h"

#include <Eigen/Geometry>

#include "common/error.h"

namespace arthrosim::musculoskeletal {

int KinematicTree::body_index(const std::string& name) const {
  for (size_t i = 0; i < bodies.size(); ++i)
    if (bodies[i].name == name) return static_cast<int>(i);
  return -1;
}

int KinematicTree::coordinate_index(const std::string& name) const {
  for (size_t i = 0; i < coordinates.size(); ++i)
    if (coordinates[i] == name) return static_cast<int>(i);
  return -1;
}

int KinematicTree::add_root(const std::string& name, double mass) {
  if (!bodies.empty()) throw common::InputError("kinematic tree: root '" + name + "' added twice");
  bodies.push_back({name, -1, mass});
  return 0;
}

int KinematicTree::add_body(const std::string& name, double mass, const Joint& j_in) {
  if (body_index(name) >= 0)
    throw common::InputError("kinematic tree: duplicate body '" + name + "'");
  if (j_in.parent < 0 || j_in.parent >= static_cast<int>(bodies.size()))
    throw common::InputError("kinematic tree: body '" + name + "' has an unknown parent body");
  Joint j = j_in;
  j.child = static_cast<int>(bodies.size());
  if (j.type != JointType::kFixed) {
    const double n = j.axis_J.norm();
    if (!(n > 0.0))
      throw common::InputError("kinematic tree: joint '" + j.name + "' has a zero axis");
    j.axis_J /= n;
    j.coordinate = static_cast<int>(coordinates.size());
    coordinates.push_back(j.name);
  } else {
    j.coordinate = -1;
  }
  bodies.push_back({name, static_cast<int>(joints.size()), mass});
  joints.push_back(j);
  return j.child;
}

void forward_kinematics(const KinematicTree& tree, const Eigen::VectorXd& q, KinematicsData& d,
                        const Pose& X_W0) {
  if (q.size() != tree.num_coordinates())
    throw common::InputError("forward kinematics: expected " +
                             std::to_string(tree.num_coordinates()) + " coordinates, found " +
                             std::to_string(q.size()));
  d.X_WB.resize(tree.bodies.size());
  d.joint_origin_W.resize(tree.joints.size());
  d.joint_axis_W.resize(tree.joints.size());
  d.X_WB[0] = X_W0;
  for (size_t b = 1; b < tree.bodies.size(); ++b) {
    const Joint& j = tree.joints[tree.bodies[b].parent_joint];
    const Pose X_WJ = d.X_WB[j.parent] * j.X_PJ;
    d.joint_origin_W[tree.bodies[b].parent_joint] = X_WJ.translation();
    d.joint_axis_W[tree.bodies[b].parent_joint] = X_WJ.linear() * j.axis_J;
    Pose M = Pose::Identity();
    if (j.type == JointType::kRevolute)
      M.linear() = Eigen::AngleAxisd(q[j.coordinate], j.axis_J).toRotationMatrix();
    else if (j.type == JointType::kPrismatic)
      M.translation() = q[j.coordinate] * j.axis_J;
    d.X_WB[b] = X_WJ * M;
  }
}

namespace {
template <class F>
void for_each_joint_to_root(const KinematicTree& tree, int body, F&& f) {
  while (body > 0) {
    const int ji = tree.bodies[body].parent_joint;
    const Joint& j = tree.joints[ji];
    if (j.coordinate >= 0) f(ji, j);
    body = j.parent;
  }
}
}  // namespace

void add_point_force(const KinematicTree& tree, const KinematicsData& d, int body,
                     const Vec3& x_W, const Vec3& f_W, Eigen::VectorXd& Q) {
  for_each_joint_to_root(tree, body, [&](int ji, const Joint& j) {
    const Vec3& a = d.joint_axis_W[ji];
    if (j.type == JointType::kRevolute)
      Q[j.coordinate] += a.cross(x_W - d.joint_origin_W[ji]).dot(f_W);
    else
      Q[j.coordinate] += a.dot(f_W);
  });
}

void add_body_couple(const KinematicTree& tree, const KinematicsData& d, int body,
                     const Vec3& tau_W, Eigen::VectorXd& Q) {
  for_each_joint_to_root(tree, body, [&](int ji, const Joint& j) {
    if (j.type == JointType::kRevolute) Q[j.coordinate] += d.joint_axis_W[ji].dot(tau_W);
  });
}

Eigen::Matrix<double, 3, Eigen::Dynamic> point_jacobian(const KinematicTree& tree,
                                                        const KinematicsData& d, int body,
                                                        const Vec3& x_W) {
  Eigen::Matrix<double, 3, Eigen::Dynamic> J =
      Eigen::Matrix<double, 3, Eigen::Dynamic>::Zero(3, tree.num_coordinates());
  for_each_joint_to_root(tree, body, [&](int ji, const Joint& j) {
    const Vec3& a = d.joint_axis_W[ji];
    J.col(j.coordinate) =
        j.type == JointType::kRevolute ? Vec3(a.cross(x_W - d.joint_origin_W[ji])) : a;
  });
  return J;
}

namespace {
Vec3 axial(const Eigen::Matrix3d& S) {
  // Axial vector of the skew part of S (mean of each antisymmetric pair).
  return 0.5 * Vec3(S(2, 1) - S(1, 2), S(0, 2) - S(2, 0), S(1, 0) - S(0, 1));
}
Eigen::Matrix3d skew(const Vec3& w) {
  Eigen::Matrix3d S;
  S << 0, -w.z(), w.y(), w.z(), 0, -w.x(), -w.y(), w.x(), 0;
  return S;
}
}  // namespace

void central_difference_rotation_rates(const std::array<Eigen::Matrix3d, 3>& R, double step, Vec3& w,
                                       Vec3& alpha) {
  const Eigen::Matrix3d Rdot = (R[2] - R[0]) / (2.0 * step);
  const Eigen::Matrix3d Rddot = (R[2] - 2.0 * R[1] + R[0]) / (step * step);
  const Eigen::Matrix3d Rt = R[1].transpose();
  w = axial(Rdot * Rt);
  alpha = axial(Rddot * Rt - skew(w) * skew(w));
}

void add_inertial_forces(const KinematicTree& tree, const Eigen::VectorXd& q,
                         const std::vector<int>& bodies, const RootMotion& motion,
                         Eigen::VectorXd& Q) {
  if (!(motion.step > 0))
    throw common::InputError("add_inertial_forces: expected a time step > 0");
  if (motion.coordinate >= tree.num_coordinates())
    throw common::InputError("add_inertial_forces: coordinate index out of range");
  KinematicsData k[3];
  for (int s = 0; s < 3; ++s) {
    const double tau = (s - 1) * motion.step;
    Eigen::VectorXd qs = q;
    if (motion.coordinate >= 0)
      qs[motion.coordinate] += tau * motion.velocity + 0.5 * tau * tau * motion.acceleration;
    forward_kinematics(tree, qs, k[s]);
  }
  const double e2 = motion.step * motion.step;
  // Lab positions relative to the root origin at tau = 0 (smaller numbers,
  // same accelerations).
  const Vec3 o = motion.X_LR[1].translation();
  const Eigen::Matrix3d R_LR = motion.X_LR[1].linear();
  const Eigen::Matrix3d R_RL = R_LR.transpose();
  const Vec3 g_R = R_RL * motion.gravity_L;
  for (int b : bodies) {
    const Body& B = tree.bodies.at(b);
    if (B.mass == 0.0 && B.inertia.isZero(0.0)) continue;
    Vec3 p[3];
    std::array<Eigen::Matrix3d, 3> R;
    for (int s = 0; s < 3; ++s) {
      const Pose X_LB = motion.X_LR[s] * k[s].X_WB[b];
      p[s] = X_LB * B.com - o;
      R[s] = X_LB.linear();
    }
    const Vec3 a_L = (p[2] - 2.0 * p[1] + p[0]) / e2;
    Vec3 w_L, alpha_L;
    central_difference_rotation_rates(R, motion.step, w_L, alpha_L);
    const Eigen::Matrix3d I_L = R[1] * B.inertia * R[1].transpose();
    const Vec3 f_R = B.mass * (g_R - R_RL * a_L);
    const Vec3 tau_R = -(R_RL * (I_L * alpha_L + w_L.cross(I_L * w_L)));
    add_point_force(tree, k[1], b, k[1].X_WB[b] * B.com, f_R, Q);
    add_body_couple(tree, k[1], b, tau_R, Q);
  }
}

}  // namespace arthrosim::musculoskeletal
