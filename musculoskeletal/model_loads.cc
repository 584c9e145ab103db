#include "musculoskeletal/model_loads.h"

#include <algorithm>
#include <array>

#include "common/error.h"

namespace arthrosim::musculoskeletal {

std::vector<BodyWrench> lab_force_wrenches(const KinematicsData& data, int ground,
                                           const std::vector<LabForce>& forces) {
  if (ground < 0 || ground >= static_cast<int>(data.X_WB.size()))
    throw common::InputError("lab_force_wrenches: the model has no ground body");
  const Pose& X_WG = data.X_WB[ground];
  const Eigen::Matrix3d& R_WG = X_WG.linear();
  std::vector<BodyWrench> w;
  for (const LabForce& f : forces) {
    const Vec3 x_W = f.has_point ? Vec3(X_WG * f.point_L) : data.X_WB.at(f.body).translation();
    w.push_back({f.body, x_W, R_WG * f.force_L, R_WG * f.torque_L});
  }
  return w;
}

std::vector<BodyWrench> lab_inertial_wrenches(const KinematicTree& tree, int ground, const Eigen::VectorXd& q,
                                              const Eigen::VectorXd& qd, const Eigen::VectorXd& qdd,
                                              const std::vector<int>& bodies, const Vec3& gravity_L,
                                              double step, KinematicsData* centre) {
  const int n = tree.num_coordinates();
  if (q.size() != n || qd.size() != n || qdd.size() != n)
    throw common::InputError("lab_inertial_wrenches: expected q, qd, qdd of size " + std::to_string(n));
  if (!(step > 0)) throw common::InputError("lab_inertial_wrenches: expected a step > 0");
  if (ground < 0 || ground >= static_cast<int>(tree.bodies.size()))
    throw common::InputError("lab_inertial_wrenches: the model has no ground body");
  KinematicsData k[3];
  for (int s = 0; s < 3; ++s) {
    const double tau = (s - 1) * step;
    forward_kinematics(tree, q + tau * qd + 0.5 * tau * tau * qdd, k[s]);
  }
  Pose X_LW[3];
  for (int s = 0; s < 3; ++s) X_LW[s] = k[s].X_WB[ground].inverse();
  const Eigen::Matrix3d R_WL = k[1].X_WB[ground].linear();
  const double h2 = step * step;
  std::vector<BodyWrench> w;
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
    w.push_back({b, k[1].X_WB[b] * B.com, R_WL * (B.mass * (gravity_L - a_L)),
                 -(R_WL * (I_L * alpha_L + w_L.cross(I_L * w_L)))});
  }
  if (centre) *centre = k[1];
  return w;
}

void add_wrenches(const KinematicTree& tree, const KinematicsData& data, const std::vector<BodyWrench>& w,
                  Eigen::VectorXd& Q) {
  for (const BodyWrench& x : w) {
    add_point_force(tree, data, x.body, x.point_W, x.force_W, Q);
    add_body_couple(tree, data, x.body, x.torque_W, Q);
  }
}

double axis_moment(const std::vector<BodyWrench>& w, const Vec3& o, const Vec3& a) {
  double m = 0.0;
  for (const BodyWrench& x : w) m += a.dot((x.point_W - o).cross(x.force_W) + x.torque_W);
  return m;
}

void add_lab_forces(const KinematicTree& tree, const KinematicsData& data, int ground,
                    const std::vector<LabForce>& forces, Eigen::VectorXd& Q) {
  add_wrenches(tree, data, lab_force_wrenches(data, ground, forces), Q);
}

void add_lab_inertial_forces(const KinematicTree& tree, int ground, const Eigen::VectorXd& q,
                             const Eigen::VectorXd& qd, const Eigen::VectorXd& qdd,
                             const std::vector<int>& bodies, Eigen::VectorXd& Q, const Vec3& gravity_L,
                             double step) {
  KinematicsData centre;
  const auto w = lab_inertial_wrenches(tree, ground, q, qd, qdd, bodies, gravity_L, step, &centre);
  add_wrenches(tree, centre, w, Q);
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
