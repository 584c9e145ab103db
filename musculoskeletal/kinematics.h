#pragma once
// Kinematic tree of rigid bodies connected by revolute, prismatic and fixed
// joints (the URDF joint model): the pose of a child body is
//   X_WC = X_WP * X_PJ * M(q),  M = rotation about / translation along the
//   joint axis (given in the joint frame J) by the joint coordinate q.
// Body 0 is the root (the femur in the knee model; its world pose is an input,
// identity by default, so "world" = femur frame unless stated).
//
// Point Jacobian (world velocity of a material point x of body b per unit qdot_j,
// for joints j between b and the root):
//   revolute  a_j x (x - o_j),  prismatic  a_j,
// with o_j, a_j the world origin and unit axis of joint j. A force f at x on b
// contributes Q_j += J_j(x) . f to the generalized forces.
#include <Eigen/Geometry>
#include <array>
#include <string>
#include <vector>

#include "common/mesh.h"

namespace arthrosim::musculoskeletal {

using common::Vec3;
using Pose = Eigen::Isometry3d;

enum class JointType { kFixed, kRevolute, kPrismatic };

struct Joint {
  std::string name;
  JointType type = JointType::kFixed;
  int parent = -1;                    ///< body index
  int child = -1;                     ///< body index
  Pose X_PJ = Pose::Identity();       ///< joint frame in the parent body
  Vec3 axis_J = Vec3::UnitZ();        ///< unit axis in the joint frame
  double lower = -1e30, upper = 1e30; ///< limits [rad or m]
  int coordinate = -1;                ///< index into q (-1 for fixed)
};

struct Body {
  std::string name;
  int parent_joint = -1;  ///< -1 for the root
  double mass = 0.0;      ///< [kg]
  /// Centre of mass in the body frame [m] (URDF <inertial><origin xyz>).
  Vec3 com = Vec3::Zero();
  /// Inertia tensor about the centre of mass, body-frame axes [kg m^2]
  /// (URDF <inertia>, rotated from the <inertial> frame).
  Eigen::Matrix3d inertia = Eigen::Matrix3d::Zero();
};

/// Constant description of the tree. Bodies are stored so that a parent always
/// precedes its children (body 0 = root).
struct KinematicTree {
  std::vector<Body> bodies;
  std::vector<Joint> joints;              ///< joints[b's parent_joint] moves b
  std::vector<std::string> coordinates;   ///< one per movable joint, in joint order

  int num_coordinates() const { return static_cast<int>(coordinates.size()); }
  int body_index(const std::string& name) const;        ///< -1 if absent
  int coordinate_index(const std::string& name) const;  ///< -1 if absent
  /// Appends a body with its joint; throws InputError on unknown parent or
  /// duplicate names. Returns the new body's index.
  int add_body(const std::string& name, double mass, const Joint& joint_to_parent);
  int add_root(const std::string& name, double mass);
};

/// Workspace of the kinematics.
struct KinematicsData {
  std::vector<Pose> X_WB;        ///< world pose of every body
  std::vector<Vec3> joint_origin_W, joint_axis_W;
};

/// Forward kinematics; q has num_coordinates() entries. X_W0 = root pose.
void forward_kinematics(const KinematicTree& tree, const Eigen::VectorXd& q, KinematicsData& data,
                        const Pose& X_W0 = Pose::Identity());

/// Q += J(body, x_W)^T f_W.
void add_point_force(const KinematicTree& tree, const KinematicsData& data, int body,
                     const Vec3& x_W, const Vec3& f_W, Eigen::VectorXd& Q);

/// Q += J_rot(body)^T tau_W (a pure couple on the body).
void add_body_couple(const KinematicTree& tree, const KinematicsData& data, int body,
                     const Vec3& tau_W, Eigen::VectorXd& Q);

/// Angular velocity w and angular acceleration alpha, in the frame the
/// rotations map into, at the middle of three orientations
/// R[k] = R(t + (k - 1) step), by central differences:
/// w = axial(Rdot R^T), alpha = axial(Rddot R^T - [w]x^2) (axial: the vector
/// of the skew part). Shared by the inverse dynamics (knee_loads.cc) and
/// add_inertial_forces.
void central_difference_rotation_rates(const std::array<Eigen::Matrix3d, 3>& R, double step, Vec3& w,
                                       Vec3& alpha);

/// Motion of the root frame R in an inertial (lab) frame L, for the
/// d'Alembert forces of add_inertial_forces: the root pose at t - step, t and
/// t + step (along the trial's local Taylor path), gravity in L and, when
/// `coordinate` >= 0, that coordinate's prescribed velocity and acceleration
/// (every other coordinate is held at its value: zero rate).
struct RootMotion {
  std::array<Pose, 3> X_LR = {Pose::Identity(), Pose::Identity(), Pose::Identity()};
  double step = 1e-4;                          ///< [s]
  Vec3 gravity_L = Vec3(0.0, -9.80665, 0.0);   ///< [m/s^2]
  int coordinate = -1;
  double velocity = 0.0, acceleration = 0.0;   ///< [rad/s, rad/s^2 or m/s, m/s^2]
};

/// Q += sum over `bodies` of the weight and d'Alembert force of each body,
///   J_b(x_b)^T m_b (g - a_b)  +  J_rot,b^T [-(I_b alpha_b + w_b x I_b w_b)],
/// with x_b the body's centre of mass and a_b, w_b, alpha_b its absolute
/// (lab) acceleration, angular velocity and angular acceleration, all
/// expressed in the root frame (= the tree's world, root pose identity). The
/// lab motion of each body is X_LR(tau) X_RB(q(tau)) at tau = -step, 0, step
/// with q(tau) = q + (tau v + tau^2/2 a) e_coordinate; a, w and alpha come
/// from central differences in tau (second order; for the body's lab
/// position ~1 m and step 1e-4 s the rounding error is ~1e-8 m/s^2).
/// Bodies with zero mass and zero inertia contribute nothing.
void add_inertial_forces(const KinematicTree& tree, const Eigen::VectorXd& q,
                         const std::vector<int>& bodies, const RootMotion& motion,
                         Eigen::VectorXd& Q);

/// 3 x n point Jacobian.
Eigen::Matrix<double, 3, Eigen::Dynamic> point_jacobian(const KinematicTree& tree,
                                                        const KinematicsData& data, int body,
                                                        const Vec3& x_W);

}  // namespace arthrosim::musculoskeletal
