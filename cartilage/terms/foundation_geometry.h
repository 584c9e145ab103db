#pragma once
// Internal to the foundation terms (foundation_springs, foundation_damping,
// periphery_fixed): per node the reference position, unit reference
// transverse direction and nodal area, and the bone-carried anchor.
#include <Eigen/Geometry>
#include <vector>

#include "cartilage/shell_model.h"
#include "common/error.h"

namespace arthrosim::cartilage {

// Shared geometry of the foundation terms: per node the reference position,
// unit reference transverse direction and nodal area; the anchor moves with
// the bone: T(t) = X_WB(t) X_WB(0)^-1.
struct FoundationGeometry {
  explicit FoundationGeometry(const ShellModel& model, BoneMotion b) : bone(std::move(b)) {
    if (!bone.pose || !bone.spatial_velocity)
      throw common::InputError("foundation: BoneMotion needs both pose and spatial_velocity callbacks");
    X_WB0_inv = bone.pose(0.0).inverse();
    const int n = model.num_nodes();
    r0.resize(n);
    n0.resize(n);
    area = model.nodal_areas();
    for (int i = 0; i < n; ++i) {
      r0[i] = model.reference_position(i);
      n0[i] = model.reference_director(i).normalized();
    }
  }
  /// Anchor point, direction and their time derivatives of node i, given the
  /// bone pose X_WB and spatial velocity V at one time.
  void at(const Eigen::Isometry3d& X_WB, const Eigen::Matrix<double, 6, 1>& V, int i, Eigen::Vector3d& p,
          Eigen::Vector3d& n, Eigen::Vector3d& p_dot, Eigen::Vector3d& n_dot) const {
    const Eigen::Isometry3d T = X_WB * X_WB0_inv;
    p = T * r0[i];
    n = T.linear() * n0[i];
    const Eigen::Vector3d w = V.head<3>();
    p_dot = V.tail<3>() + w.cross(p - X_WB.translation());
    n_dot = w.cross(n);
  }
  /// Calls f(i, p, n, p_dot, n_dot) for every node i in order, with its
  /// anchor at time t.
  template <class F>
  void for_each_node(double t, F&& f) const {
    const Eigen::Isometry3d X = bone.pose(t);
    const Eigen::Matrix<double, 6, 1> V = bone.spatial_velocity(t);
    for (int i = 0; i < static_cast<int>(r0.size()); ++i) {
      Eigen::Vector3d p, n, pd, nd;
      at(X, V, i, p, n, pd, nd);
      f(i, p, n, pd, nd);
    }
  }
  BoneMotion bone;
  Eigen::Isometry3d X_WB0_inv;
  std::vector<Eigen::Vector3d> r0, n0;
  Eigen::VectorXd area;
};

}  // namespace arthrosim::cartilage
