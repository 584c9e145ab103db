#pragma once
// The musculoskeletal knee model: a kinematic tree (femur root; tibia and
// patella on 6-DOF chains; pelvis and calcaneus on prescribed hip and ankle
// joints, used only to place muscle points), ligament groups of Blankevoort
// bundles, muscles (force = activation x F_max along the path, as COMAK does)
// and elastic-foundation contact pairs. Model is constant; ModelData holds all
// workspaces and results (Pinocchio-style split). Loaded from URDF with
// arthrosim extension elements, see docs/model_format.md and model_io.h.
//
// Generalized forces. Every term is a set of forces on bodies; with the point
// Jacobians of kinematics.h,
//   Q = sum_bundles f_b r_b + sum_muscles a_m F_m r_m + sum_pairs J^T W_pair,
// where r = -dl/dq is the moment-arm vector of a path (from its force
// applications per unit tension) and W_pair the contact wrench on each body.
// dQ/dq is computed by central differences of Q (see evaluate_jacobian),
// re-evaluating in each column only the terms on bodies that column moves.
#include <Eigen/Core>
#include <map>
#include <string>
#include <vector>

#include "musculoskeletal/contact.h"
#include "musculoskeletal/kinematics.h"
#include "musculoskeletal/ligament.h"
#include "musculoskeletal/path.h"

namespace arthrosim::musculoskeletal {

struct LigamentBundle {
  std::string name;  ///< optional (an imported model keeps OpenSim's bundle names)
  BlankevoortParameters parameters;
  Path path;
};

/// A generalized spring-damper on one coordinate (OpenSim's
/// SpringGeneralizedForce): Q_c = -stiffness (q_c - rest_length) - viscosity qdot_c
/// [N m or N], stiffness [N m/rad or N/m], viscosity [N m s/rad or N s/m].
struct CoordinateSpring {
  std::string name;
  int coordinate = -1;
  double stiffness = 0.0, rest_length = 0.0, viscosity = 0.0;
};

/// A named group of bundles (e.g. "MCLs" with 6 bundles).
struct Ligament {
  std::string name;
  std::vector<LigamentBundle> bundles;
};

struct Muscle {
  std::string name;
  double max_isometric_force = 0.0;  ///< F_max [N], > 0
  /// Pennation angle at optimal fibre length [rad] (recorded from the model
  /// file; COMAK's force a F_max along the path does not use it).
  double pennation_angle = 0.0;
  /// Optimal fibre length l_opt and tendon slack length l_ts [m] (both > 0,
  /// or both 0 = not given). Used only by ForceOptions::force_length.
  double optimal_fiber_length = 0.0;
  double tendon_slack_length = 0.0;
  Path path;
};

/// Active force-length factor of Thelen (2003), f_L = exp(-(l~ - 1)^2 / gamma),
/// l~ = (l_path - l_ts) / l_opt (rigid tendon, no pennation), gamma = the
/// width parameter (Thelen: 0.45). f_L(1) = 1; f_L = 0.574 at l~ = 0.5 and 1.5.
double active_force_length(double normalized_fiber_length, double gamma = 0.45);

class Model {
 public:
  std::string name;
  std::string source;  ///< file it was loaded from (for messages)
  KinematicTree tree;
  std::vector<Ligament> ligaments;
  std::vector<Muscle> muscles;
  std::vector<ContactPair> contacts;
  std::vector<CoordinateSpring> coordinate_springs;
  /// Coordinates solved for (the 12 knee DOF) and prescribed (hip, ankle),
  /// indices into tree.coordinates.
  std::vector<int> free_coordinates, prescribed_coordinates;
  /// Mass of the whole subject [kg] (for body-weight units and a trial that
  /// gives none): <arthrosim:subject mass_kg> (an imported model records the
  /// source model's total, which includes bodies it did not import), else the
  /// sum of the link masses.
  double subject_mass_kg = 0.0;
  /// Default value of every coordinate (<arthrosim:default>; zero unless
  /// given): the neutral pose a solver starts from when it has nothing better
  /// (an imported patella sits 53 mm in front of the knee at its default).
  Eigen::VectorXd default_q;
  /// Roles (<arthrosim:role>): which coordinate is the "knee_flexion",
  /// "hip_flexion", ... and which body is the "femur", "tibia", "patella",
  /// for models whose names are not arthrosim's (an imported OpenSim model).
  std::map<std::string, int> coordinate_roles, body_roles;
  /// The coordinate with that role: its role entry, else the coordinate
  /// named like the role, else -1.
  int role_coordinate(const std::string& role) const;
  /// The body with that role: its role entry, else the body named like it, else -1.
  int role_body(const std::string& role) const;

  int num_coordinates() const { return tree.num_coordinates(); }
  int num_bundles() const;
  int ligament_index(const std::string& name) const;  ///< -1 if absent
  int muscle_index(const std::string& name) const;    ///< -1 if absent
  int contact_index(const std::string& name) const;   ///< -1 if absent
};

/// Which terms to evaluate (a term not asked for costs nothing).
struct ForceOptions {
  bool ligaments = true;
  bool muscles = true;
  bool contact = true;
  /// The model's coordinate springs (Model::coordinate_springs).
  bool coordinate_springs = true;
  /// Muscle force a F_max f_L(l~) instead of a F_max (COMAK's default, off):
  /// every muscle must then give optimal_fiber_length and tendon_slack_length.
  bool force_length = false;
  /// gamma of active_force_length [-] (Thelen 2003: 0.45), > 0.
  double force_length_width = 0.45;
  /// Central-difference step for dQ/dq [rad or m]. 1e-6: small against the
  /// scale of the kinematics (~1 rad, ~1e-2 m), large against the round-off of
  /// Q (~1e-16 x 1e3 N / 1e-6 = 1e-7 N per unit q) and against the faceting
  /// noise of the contact depth on ~0.5 mm triangles.
  double jacobian_step = 1e-6;
  /// evaluate_jacobian: in the column of coordinate c, evaluate only the
  /// terms (bundles, muscles, contact pairs) attached to a body that c moves;
  /// the others give the same force at q +- h and a zero difference. Same
  /// Jacobian up to rounding (~1e-16 |Q| / h); false only to compare.
  bool jacobian_skip_unmoved_terms = true;
};

struct BundleResult {
  PathState path;
  BlankevoortForce force;
};

struct ModelData {
  KinematicsData kinematics;
  std::vector<std::vector<BundleResult>> ligaments;  ///< [ligament][bundle]
  std::vector<PathState> muscle_paths;
  Eigen::VectorXd muscle_forces;                     ///< [N]
  /// f_L per muscle (1 without ForceOptions::force_length).
  Eigen::VectorXd muscle_force_length;
  std::vector<ContactPairData> contacts;
  /// Generalized forces by term and in total (one entry per coordinate;
  /// N m for revolute, N for prismatic).
  Eigen::VectorXd Q_ligaments, Q_muscles, Q_contact, Q_springs, Q;
  /// dQ/dq (n x n), filled by evaluate_jacobian.
  Eigen::MatrixXd dQ_dq;
};

ModelData make_data(const Model& model);

/// Forward kinematics and all requested forces at coordinates q, speeds qdot
/// (ligament damping; zeros for statics) and muscle activations (one per
/// muscle, or empty for zero). Throws InputError on size mismatch and
/// NumericalError on a non-finite result (naming the term).
void evaluate_forces(const Model& model, ModelData& data, const Eigen::VectorXd& q,
                     const Eigen::VectorXd& qdot, const Eigen::VectorXd& activations,
                     const ForceOptions& options = {});

/// evaluate_forces at q, then dQ/dq by central differences over the given
/// coordinates (columns; all if empty). Other columns are zero. Results of the
/// centre evaluation are left in data.
void evaluate_jacobian(const Model& model, ModelData& data, const Eigen::VectorXd& q,
                       const Eigen::VectorXd& qdot, const Eigen::VectorXd& activations,
                       const ForceOptions& options = {}, const std::vector<int>& columns = {});

/// Moment-arm vector r = -dl/dq of a path at the current kinematics.
Eigen::VectorXd moment_arms(const Model& model, const ModelData& data, const PathState& path);

}  // namespace arthrosim::musculoskeletal
