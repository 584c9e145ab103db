#pragma once
// Helpers shared by the mesh-contact tests (tests/cartilage/mesh_contact_test.cc,
// tests/stability/contact_stability_test.cc).
#include <Eigen/Geometry>

#include "cartilage/shell_model.h"

namespace arthrosim::cartilage::testing {

/// A bone translating with constant velocity v from the identity at t = 0.
inline BoneMotion translating_bone(const Eigen::Vector3d& v) {
  BoneMotion b;
  b.pose = [v](double t) {
    Eigen::Isometry3d X = Eigen::Isometry3d::Identity();
    X.translation() = t * v;
    return X;
  };
  b.spatial_velocity = [v](double) {
    Eigen::Matrix<double, 6, 1> V = Eigen::Matrix<double, 6, 1>::Zero();
    V.tail<3>() = v;
    return V;
  };
  return b;
}

/// Area-weighted mean displacement along the unit normal n of the nodes of
/// `model` whose reference positions lie within `radius` of the line through
/// `centre` along n, measured from their reference positions shifted by
/// `bone_shift` (the bone's motion), times `sign`.
inline double mean_normal_deflection(const ShellModel& model, const Eigen::VectorXd& q, const Eigen::Vector3d& centre,
                                     const Eigen::Vector3d& n, double radius, const Eigen::Vector3d& bone_shift,
                                     double sign) {
  double sum = 0, area = 0;
  for (int i = 0; i < model.num_nodes(); ++i) {
    const Eigen::Vector3d r0 = model.reference_position(i);
    const Eigen::Vector3d rel = r0 - centre;
    if ((rel - rel.dot(n) * n).norm() > radius) continue;
    sum += model.nodal_areas()(i) * sign * (q.segment<3>(6 * i) - (r0 + bone_shift)).dot(n);
    area += model.nodal_areas()(i);
  }
  return sum / area;
}

}  // namespace arthrosim::cartilage::testing
