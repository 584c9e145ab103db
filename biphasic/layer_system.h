#pragma once
// Galerkin matrices of the linear biphasic u-p equations (seed 000, eqs 8-9)
// on a layer mesh.
//
// Strong form (small strain, both phases intrinsically incompressible):
//   div(sigma_E(u) - p I) = 0,   sigma_E = lambda tr(eps) I + 2 mu eps,
//   div(v - k grad p) = 0,       v = du/dt (solid velocity).
// Weak form with test functions w (displacement space) and q (pressure space):
//   int eps(w) : sigma_E(u) dV - int p div w dV = int_Gt w . t dG
//   -int q div v dV - int grad q . k grad p dV = int_GQ q Qbar dG
// (Qbar = -k grad p . n, the outward relative fluid flux). In matrix form this is
// the seed's first-order system (14):
//   [0    -A] [v]   [K 0] [u]   [F_t]
//   [-A^T -B] [p] + [0 0] [0] = [F_Q]
// with
//   K_(ai)(bj) = int lambda d_i N_a d_j N_b + mu (d_j N_a d_i N_b + delta_ij grad N_a . grad N_b) dV
//   A_(ai)c    = int d_i N_a M_c dV
//   B_cd       = int k grad M_c . grad M_d dV
// N_a: displacement basis, M_c: pressure basis (trilinear).
//
// Element pairs:
//   kTaylorHood  triquadratic displacement (27 nodes) with trilinear pressure
//                (8 corner nodes): inf-sup stable (Q2-Q1), the default;
//   kEqualOrder  trilinear displacement and pressure (Q1-Q1): NOT inf-sup
//                stable; kept to show the pressure oscillation it produces
//                after a step load (tests/biphasic/step_load_oscillation_test.cc).
//
// Unknown ordering: u-dof 3 * node + component (node: the displacement node
// set of the pair), then p-dof = corner node index (LayerMesh::q1_node).
#include <Eigen/Core>
#include <Eigen/SparseCore>
#include <vector>

#include "biphasic/layer_mesh.h"
#include "biphasic/material.h"

namespace arthrosim::biphasic {

enum class ElementPair { kTaylorHood, kEqualOrder };
const char* to_string(ElementPair pair);

struct LayerSystem {
  LayerMesh mesh;
  /// Material of each element layer (index L = 0 at the bone); all equal for
  /// a single-material layer.
  std::vector<Material> materials;
  ElementPair pair = ElementPair::kTaylorHood;

  Eigen::SparseMatrix<double> K;  ///< nu x nu solid stiffness [N/m]
  Eigen::SparseMatrix<double> A;  ///< nu x np coupling [m^2]
  Eigen::SparseMatrix<double> B;  ///< np x np fluid "stiffness" [m^5/(N s)]
  /// nu x (3 nv): maps articular-surface vertex tractions (3 per vertex,
  /// bilinear interpolation on each quad) to the consistent load vector F_t:
  /// F_t = surface_load * t, t = [t_0x t_0y t_0z t_1x ...] [Pa] -> [N].
  Eigen::SparseMatrix<double> surface_load;

  /// Material of element layer L.
  const Material& material(int L = 0) const { return materials[L]; }
  /// Material of an element.
  const Material& element_material(int element) const { return materials[element % mesh.layers]; }
  /// Polynomial order of the displacement basis (2 Taylor-Hood, 1 equal order).
  int u_order() const { return pair == ElementPair::kTaylorHood ? 2 : 1; }
  /// Displacement node positions (q2_nodes or q1_nodes of the mesh).
  const common::Points3& u_nodes() const {
    return pair == ElementPair::kTaylorHood ? mesh.q2_nodes : mesh.q1_nodes;
  }
  int num_u_nodes() const { return static_cast<int>(u_nodes().rows()); }
  int num_u_dofs() const { return 3 * num_u_nodes(); }
  int num_p_dofs() const { return mesh.num_q1_nodes(); }
  /// Element displacement node of local index a.
  int u_node(int element, int a) const {
    return pair == ElementPair::kTaylorHood ? mesh.hex_q2(element, a) : mesh.hex_q1(element, a);
  }
};

/// Assembles K, A, B and the surface load operator (Gauss 3^3 for Q2, 2^3 for
/// Q1 in the volume; 3 x 3 on faces). Validates the material (InputError).
LayerSystem assemble_layer(LayerMesh mesh, const Material& material,
                           ElementPair pair = ElementPair::kTaylorHood);
/// As above with one material per element layer (size mesh.layers): a layered
/// column whose interfaces are tied (shared nodes: continuous displacement and
/// pressure), e.g. two cartilage layers bonded at their contact surface.
LayerSystem assemble_layer(LayerMesh mesh, const std::vector<Material>& layer_materials,
                           ElementPair pair = ElementPair::kTaylorHood);

/// Stress and flux at one point of an element.
struct PointFields {
  Eigen::Matrix3d strain;          ///< small strain [-]
  Eigen::Matrix3d effective_stress;  ///< sigma_E [Pa], tension positive
  Eigen::Matrix3d total_stress;    ///< sigma_E - p I [Pa]
  double pressure = 0.0;           ///< p [Pa]
  Eigen::Vector3d flux;            ///< relative fluid flux w = -k grad p [m/s]
};

/// Fields at reference point xi of `element` from the u-dof vector u and the
/// p-dof vector p.
PointFields evaluate_point(const LayerSystem& system, int element, const Eigen::Vector3d& xi,
                           const Eigen::VectorXd& u, const Eigen::VectorXd& p);

}  // namespace arthrosim::biphasic
