#pragma once
// Nodal fields of a layer solution for output and the per-frame indicators:
// stresses and fluid flux at the corner (pressure) nodes, averaged over the
// elements sharing the node (each element evaluated at its own corner), the
// maximum tensile (first principal) stress of the solid matrix on the
// articular surface and the maximum shear stress at the cartilage-bone
// interface.
//
// Symmetric tensors are stored as 6 components in the order
// xx, yy, zz, xy, yz, xz [Pa], in the layer's (bone) frame.
#include <Eigen/Core>

#include "biphasic/layer_system.h"

namespace arthrosim::biphasic {

struct NodalFields {
  common::Points3 displacement;                  ///< per corner node [m]
  Eigen::VectorXd pressure;                      ///< per corner node [Pa]
  Eigen::Matrix<double, Eigen::Dynamic, 6> effective_stress;  ///< sigma_E [Pa]
  Eigen::Matrix<double, Eigen::Dynamic, 6> total_stress;      ///< sigma_E - p I [Pa]
  common::Points3 flux;                          ///< relative fluid flux -k grad p [m/s]
  /// Largest principal value of sigma_E (tension positive) [Pa].
  Eigen::VectorXd max_principal;
  /// Maximum shear stress (sigma_1 - sigma_3) / 2 (the same for sigma_E and
  /// the total stress) [Pa].
  Eigen::VectorXd max_shear;
};

/// Fields at every corner node from the u- and p-dof vectors.
NodalFields nodal_fields(const LayerSystem& system, const Eigen::VectorXd& u, const Eigen::VectorXd& p);

/// Sorted eigenvalues (ascending) of a symmetric tensor in the 6-component order.
Eigen::Vector3d principal_values(const Eigen::Matrix<double, 1, 6>& s);

/// 6-component form of a symmetric 3 x 3 tensor and back.
Eigen::Matrix<double, 1, 6> to_voigt(const Eigen::Matrix3d& s);
Eigen::Matrix3d from_voigt(const Eigen::Matrix<double, 1, 6>& s);

}  // namespace arthrosim::biphasic
