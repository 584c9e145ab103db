#pragma once
// Loads on a model with its own leg: an imported OpenSim model whose tree
// reaches the ground (a body with the role "ground", reached from the femur
// root through the reversed hip and pelvis joints; musculoskeletal/osim_import.h).
// Its lab motion follows from its own joints, so COMAK needs no generic leg
// chain (knee_loads.h): the external forces of the trial act on the model's
// foot bodies where the trial says, and every body the knee's coordinates
// move carries its own weight and d'Alembert force (docs/comak.md, "Model
// dynamics").
//
// Frames. The tree's world W is the root's frame (the femur); the lab L is
// the ground body's frame: X_LW = X_WG^-1 from the forward kinematics, so
// gravity g_L = (0, -9.80665, 0) and the trial's forces (lab frame) are
// rotated into W by R_WG.
//
// External forces: Q += J_b(x_W)^T F_W + J_rot,b^T T_W with F_W = R_WG F_L,
// x_W = X_WG p_L (the point of application), T_W = R_WG T_L (free torque).
//
// Weight and d'Alembert forces: for each body b of `bodies` with mass m_b,
// centre of mass c_b and inertia I_b (about c_b, body axes),
//   Q += J_b(c_W)^T R_WL m_b (g_L - a_L) + J_rot,b^T R_WL [-(I_L alpha_L + w_L x I_L w_L)],
// where a_L, w_L, alpha_L are the body's lab acceleration, angular velocity
// and angular acceleration from central differences of its lab pose
// X_LB(s) = X_WG(q(s))^-1 X_WB(q(s)) along the coordinates' Taylor path
// q(s) = q + s qd + s^2/2 qdd, s = -h, 0, h (h = 1e-4 s; the same path and
// step as knee_loads.h and add_inertial_forces), and I_L = R_LB I_b R_LB^T.
#include <Eigen/Core>
#include <vector>

#include "musculoskeletal/kinematics.h"

namespace arthrosim::musculoskeletal {

/// A force of the trial acting on a body of the model, in the lab frame.
struct LabForce {
  int body = -1;
  Vec3 force_L = Vec3::Zero();   ///< [N]
  Vec3 point_L = Vec3::Zero();   ///< [m]; used when has_point
  Vec3 torque_L = Vec3::Zero();  ///< free torque [N m]
  bool has_point = true;         ///< false: the force acts at the body origin
};

/// A force and a couple on one body, world frame (the tree's root frame).
struct BodyWrench {
  int body = -1;
  Vec3 point_W = Vec3::Zero();   ///< where the force acts [m]
  Vec3 force_W = Vec3::Zero();   ///< [N]
  Vec3 torque_W = Vec3::Zero();  ///< couple [N m]
};

/// The wrenches of `forces` at the kinematics in `data`.
std::vector<BodyWrench> lab_force_wrenches(const KinematicsData& data, int ground,
                                           const std::vector<LabForce>& forces);
/// The weight and d'Alembert wrenches of `bodies` (see the header), with the
/// forward kinematics at q left in *centre when given.
std::vector<BodyWrench> lab_inertial_wrenches(const KinematicTree& tree, int ground, const Eigen::VectorXd& q,
                                              const Eigen::VectorXd& qd, const Eigen::VectorXd& qdd,
                                              const std::vector<int>& bodies,
                                              const Vec3& gravity_L = Vec3(0.0, -9.80665, 0.0),
                                              double step = 1e-4, KinematicsData* centre = nullptr);
/// Q += J_b(point)^T force + J_rot,b^T torque for every wrench.
void add_wrenches(const KinematicTree& tree, const KinematicsData& data, const std::vector<BodyWrench>& w,
                  Eigen::VectorXd& Q);
/// sum of a . ((point - o) x force + torque): the wrenches' moment about the
/// axis through o along the unit vector a.
double axis_moment(const std::vector<BodyWrench>& w, const Vec3& o, const Vec3& a);

/// Q += generalized forces of `forces` at the kinematics in `data` (ground =
/// the index of the ground body).
void add_lab_forces(const KinematicTree& tree, const KinematicsData& data, int ground,
                    const std::vector<LabForce>& forces, Eigen::VectorXd& Q);

/// Q += weight and d'Alembert generalized forces of `bodies` (see the header)
/// at q with coordinate rates qd, qdd (all coordinates). Bodies without mass
/// and inertia contribute nothing.
void add_lab_inertial_forces(const KinematicTree& tree, int ground, const Eigen::VectorXd& q,
                             const Eigen::VectorXd& qd, const Eigen::VectorXd& qdd,
                             const std::vector<int>& bodies, Eigen::VectorXd& Q,
                             const Vec3& gravity_L = Vec3(0.0, -9.80665, 0.0), double step = 1e-4);

/// The bodies whose pose changes with any of `coordinates` (below their joints).
std::vector<int> bodies_moved_by(const KinematicTree& tree, const std::vector<int>& coordinates);

}  // namespace arthrosim::musculoskeletal
