#pragma once
// Building blocks of the deformable-surface stage (issue 5; seed
// seeds/002_3ffcc11eb7a447d9.txt, "Deformable Cartilage Model" and
// "Simulation of Superficial Cartilage Mechanics"):
//  - build_surface_model: one ShellModel for one cartilage (or generic) quad
//    surface with exactly the effects a scenario lists, each recorded in the
//    EffectLedger by the model at construction;
//  - nodal_strains: per-node in-plane Green-Lagrange strain, principal strains
//    and the first principal direction (docs/surface_output.md).
//
// Geometry convention (prepared model, docs/prepared_model.md): node normals
// point away from the bone, towards the joint space; quads are
// counter-clockwise seen from the joint space. The shell director is the node
// normal, so the internal face (towards the bone) is zeta = -1, and a positive
// osmotic pressure on it pushes the surface outwards (the cartilage swells).
#include <Eigen/Core>
#include <memory>
#include <string>
#include <vector>

#include <map>

#include "cartilage/shell_model.h"
#include "cartilage/shell_scene.h"
#include "common/mesh.h"
#include "common/options.h"

namespace arthrosim::common {
class EffectLedger;
}

namespace arthrosim::cartilage {

/// Node sets and loads of the generic case (any quad mesh, scene keys
/// fixed_box_mm, load_box_mm, point_load_n, pressure_mpa, displaced_box_mm,
/// displacement_mm). Loads and prescribed displacements grow linearly from 0
/// at t = 0 to their value at t = ramp_time_s, then stay constant.
struct GenericLoads {
  std::vector<int> fixed_nodes;      ///< clamped: positions and directors (effect fixed_nodes)
  std::vector<int> load_nodes;       ///< share total_force_N equally (effect point_loads)
  Eigen::Vector3d total_force_N = Eigen::Vector3d::Zero();
  double pressure_Pa = 0;            ///< on the mid-surface, along the directors (effect pressure)
  std::vector<int> displaced_nodes;  ///< positions prescribed (effect prescribed_displacement)
  Eigen::Vector3d displacement_m = Eigen::Vector3d::Zero();
  double ramp_time_s = 1;            ///< > 0
  /// Masked constraints on named node sets (scene key constraints): those
  /// without values are built by fixed_nodes, those with values by
  /// prescribed_displacement (reached at ramp_time_s).
  struct SetConstraint {
    ConstraintDefinition definition;
    std::vector<int> nodes;  ///< sorted, non-empty
  };
  std::vector<SetConstraint> constraints;
  /// Nodal forces [N] of the scene key loads at full value (point_loads),
  /// ramped like total_force_N.
  std::vector<std::pair<int, Eigen::Vector3d>> set_loads_N;
  /// Scene key histories (by name); constraints name theirs in
  /// definition.history ("" = the ramp).
  std::map<std::string, HistoryDefinition> histories;
  /// Nodal forces [N] of the loads with a history, at factor 1, per history
  /// name (point_loads; one term per history).
  std::map<std::string, std::vector<std::pair<int, Eigen::Vector3d>>> history_loads_N;
};

/// One surface to simulate.
struct SurfaceInput {
  std::string name;            ///< e.g. "femur"; part name in the ledger
  common::QuadMesh mesh;       ///< nodes [m], quads counter-clockwise seen from the joint space
  common::Points3 normals;     ///< unit node normals (N x 3), away from the bone
  std::vector<int> periphery;  ///< outline nodes (sorted); may be empty for generic meshes
  GenericLoads generic;        ///< used only by the generic effects
};

/// Material and effect parameters (SI). Defaults: seed 002 values; they are
/// the scene's defaults too (declare()).
struct SurfaceParameters {
  ShellMaterial material;                   ///< E 400 MPa, nu 0.3, rho 1000 kg/m^3
  double shell_thickness_m = 1 * common::units::mm;  ///< constant shell thickness [m], > 0
  /// k [N/m^3] (0.7 N/mm^3)
  double foundation_stiffness_N_m3 = 0.7 * common::units::n_per_mm3;
  /// c [N s/m^3] (7e6 N s/mm^3)
  double foundation_damping_N_s_m3 = 7e6 * common::units::n_s_per_mm3;
  double osmotic_pressure_Pa = 0.2 * common::units::mpa;  ///< on the internal face [Pa]
  /// > 0: the osmotic pressure rises from 0 to its value over this time with
  /// a smoothstep (e.g. during the seating of imposed kinematics) instead of
  /// acting in full from t = 0 [s].
  double osmotic_ramp_s = 0;
  /// If non-empty (one value per node, N/m^3), used by foundation_springs
  /// instead of foundation_stiffness_N_m3, e.g. k_i = K / h_i matched to the
  /// musculoskeletal stage's elastic-foundation contact (see
  /// matched_foundation_stiffness).
  Eigen::VectorXd foundation_stiffness_per_node_N_m3;
  /// foundation_springs at the nodes (the seed's) or integrated over each
  /// element (ShellModel::add_foundation_springs).
  FoundationIntegration foundation_integration = FoundationIntegration::kNodal;
  /// periphery_fixed: 0 clamps the boundary nodes to the bone (all six
  /// coordinates, the seed's condition); > 0 ties them to the bone in their
  /// tangent plane only, with this stiffness per unit area [N/m^3], leaving
  /// the normal to the foundation and the directors free
  /// (ShellModel::add_periphery_tangential).
  double periphery_tie_N_m3 = 0;

  /// Scene keys (common/options.h): shell_thickness_mm, youngs_modulus_mpa,
  /// poisson_ratio, density_kg_per_m3, foundation_stiffness_n_per_mm3,
  /// foundation_damping_n_s_per_mm3, osmotic_pressure_mpa, osmotic_ramp_s.
  void declare(common::OptionVisitor& v);
  /// "" when thickness > 0, E > 0 and -1 < nu < 0.5 (the open ends the
  /// declared closed ranges cannot express), else what is wrong.
  std::string check_material() const;
};

/// Per-node foundation modulus of an elastic layer of thickness h_i with the
/// elastic-foundation modulus K = (1 - nu) E / ((1 + nu)(1 - 2 nu)) of the
/// musculoskeletal stage's contact (Bei & Fregly 2004): k_i = K / h_i. Two
/// such layers in series reproduce that stage's p = K d / (h_1 + h_2).
/// Throws InputError naming `where` for a thickness <= 0 or bad E, nu.
Eigen::VectorXd matched_foundation_stiffness(const Eigen::VectorXd& thickness_m, double youngs_modulus_Pa,
                                             double poisson_ratio, const std::string& where);

/// Builds the shell model of one surface with its internal forces and the
/// listed effects (foundation_springs, foundation_damping, osmotic_pressure,
/// periphery_fixed, inertia; for generic meshes also fixed_nodes,
/// point_loads, pressure, prescribed_displacement with the node sets of
/// surface.generic, an empty set being an error). Each term is recorded in
/// `ledger` (part = surface name) by the model when it is constructed.
/// mesh_contact is accepted and left to the caller (it couples two models:
/// CoupledShellSystem::add_contact). Any other effect name throws InputError
/// naming it before anything is built: an effect is never silently ignored. `bone`
/// moves the foundation anchors and the fixed periphery; imposed_kinematics
/// means `bone` comes from a kinematics file (it must not be at rest) and is
/// recorded with count 1 per surface.
std::unique_ptr<ShellModel> build_surface_model(const SurfaceInput& surface, const SurfaceParameters& parameters,
                                                const std::vector<std::string>& effects, const BoneMotion& bone,
                                                common::EffectLedger* ledger);

/// Rigid bone motion interpolated from sampled poses (a kinematics file's
/// /bodies/<bone>/X_W): simulation time t corresponds to times[0] + t.
/// Between samples the translation is linear and the rotation a slerp, so the
/// spatial velocity is constant per interval: w_W = axis-angle(R_1 R_0^T) / dt,
/// v_WBo_W = (p_1 - p_0) / dt. Before the first / after the last sample the
/// pose is held (zero velocity). times strictly increasing, >= 1 sample;
/// otherwise InputError naming `source`.
BoneMotion interpolated_bone_motion(std::vector<double> times, std::vector<Eigen::Isometry3d> poses,
                                    const std::string& source);

/// Per-node tangent basis of the strain output: a1 = the world axis x
/// projected onto the plane normal to the reference director n and
/// normalised (the world axis y when |x . n| > 0.9), a2 = n x a1.
struct NodeBasis {
  common::Points3 a1, a2, n;  ///< N x 3 each, unit
};
NodeBasis node_strain_basis(const ShellModel& model);

/// Strains at the nodes (mid-surface, zeta = 0) for the state q.
struct NodalStrains {
  Eigen::MatrixXd E;       ///< N x 3: E_a1a1, E_a2a2, E_a1a2 (tensor components) in NodeBasis
  Eigen::VectorXd e1, e2;  ///< principal in-plane strains, e1 >= e2
  Eigen::MatrixXd e1_dir;  ///< N x 3 unit vector (world) of e1; sign: a1 . dir >= 0
};

/// Each element's in-plane strain tensor (E11, E22, E12 in its local frame,
/// ShellElement::strain at the corner node, zeta = 0) is rotated into world
/// components, projected on the node's basis, and averaged with equal weights
/// over the elements sharing the node.
NodalStrains nodal_strains(const ShellModel& model, const NodeBasis& basis, const Eigen::VectorXd& q);

/// Deflection along the reference director per node: (r_i - r_i0) . n_i [m].
Eigen::VectorXd nodal_deflection(const ShellModel& model, const Eigen::VectorXd& q);
/// Displacement r_i - r_i0 per node (N x 3) [m].
Eigen::MatrixXd nodal_displacement(const ShellModel& model, const Eigen::VectorXd& q);
/// The same relative to the bone's rigid motion T = X_WB(t) X_WB(0)^-1:
/// u_i = r_i - T r_i0 (world components) and w_i = u_i . (R_T n_i), so a
/// surface carried rigidly by its bone has zero displacement and deflection.
Eigen::MatrixXd nodal_displacement(const ShellModel& model, const Eigen::VectorXd& q, const Eigen::Isometry3d& T);
Eigen::VectorXd nodal_deflection(const ShellModel& model, const Eigen::VectorXd& q, const Eigen::Isometry3d& T);

}  // namespace arthrosim::cartilage
