#include "musculoskeletal/model_loads.h"

#include <algorithm>
#include <array>

#include "common/error.h"

namespace arthrosim::musculoskeletal {

void add_lab_forces(const KinematicTree& tree, const KinematicsData& data, int ground,
                    const std::vector<LabForce>& forces, Eigen::VectorXd& Q) {
  if (ground < 0 || ground >= static_cast<int>(data.X_WB.size()))
    throw common::InputError("add_lab_forces: the model has no ground body");
  const Pose& X_WG = data.X_WB[ground];
  const Eigen::Matrix3d& R_WG = X_WG.linear();
  for (const LabForce& f : forces) {
    const Vec3 x_W = f.has_point ? Vec3(X_WG * f.point_L) : data.X_WB.at(f.body).translation();
    add_point_force(tree, data, f.body, x_W, R_WG * f.force_L, Q);
    add_body_couple(tree, data, f.body, R_WG * f.torque_L, Q);
  }
}

void add_lab_inertial_forces(const KinematicTree& tree, int ground, const Eigen::VectorXd& q,
                             const Eigen::VectorXd& qd, const Eigen::VectorXd& qdd,
                             const std::vector<int>& bodies, Eigen::VectorXd& Q, const Vec3& gravity_L,
                             double step) {
  const int n = tree.num_coordinates();
  if (q.size() != n || qd.size() != n || qdd.size() != n)
    throw common::InputError("add_lab_inertial_forces: expected q, qd, qdd of size " + std::to_string(n));
  if (!(step > 0)) throw common::InputError("add_lab_inertial_forces: expected a step > 0");
  if (ground < 0 || ground >= static_cast<int>(tree.bodies.size()))
    throw common::InputError("add_lab_inertial_forces: the model has no ground body");
  KinematicsData k[3];
  for (int s = 0; s < 3; ++s) {
    const double tau = (s - 1) * step;
    forward_kinematics(tree, q + tau * qd + 0.5 * tau * tau * qdd, k[s]);
  }
  Pose X_LW[3];
  for (int s = 0; s < 3; ++s) X_LW[s] = k[s].X_WB[ground].inverse();
  const Eigen::Matrix3d R_WL = k[1].X_WB[ground].linear();
  const double h2 = step * step;
  for (int b : bodies) {
    const Body& B = tree.bodies.at(b);
    if (B.mass == 0.0 && B.inertia.isZero(0.0)) continue;
    Vec3 p[3];
    std::array<Eigen::Matrix3d, 3> R;
    for (int s = 0; s < 3; ++s) {
      const Pose X_LB = X_LW[s] * k[s].X_WB[b];
      p[s] = X_LB * B.com;
      R[s] = X_LB.linear();
    }
    // Lab positions relative to the middle one (small numbers, same accelerations).
    const Vec3 a_L = ((p[2] - p[1]) - (p[1] - p[0])) / h2;
    Vec3 w_L, alpha_L;
    central_difference_rotation_rates(R, step, w_L, alpha_L);
    const Eigen::Matrix3d I_L = R[1] * B.inertia * R[1].transpose();
    const Vec3 f_W = R_WL * (B.mass * (gravity_L - a_L));
    const Vec3 tau_W = -(R_WL * (I_L * alpha_L + w_L.cross(I_L * w_L)));
    add_point_force(tree, k[1], b, k[1].X_WB[b] * B.com, f_W, Q);
    add_body_couple(tree, k[1], b, tau_W, Q);
  }
}

std::vector<int> bodies_moved_by(const KinematicTree& tree, const std::vector<int>& coordinates) {
  std::vector<char> moved(tree.bodies.size(), 0);
  std::vector<int> out;
  for (size_t b = 1; b < tree.bodies.size(); ++b) {
    const Joint& j = tree.joints[tree.bodies[b].parent_joint];
    moved[b] = moved[j.parent] ||
               std::find(coordinates.begin(), coordinates.end(), j.coordinate) != coordinates.end();
    if (moved[b]) out.push_back(static_cast<int>(b));
  }
  return out;
}

}  // namespace arthrosim::musculoskeletal
