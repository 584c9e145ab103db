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
#include <string>
#include <vector>

#include "musculoskeletal/contact.h"
#include "musculoskeletal/kinematics.h"
#include "musculoskeletal/ligament.h"
#include "musculoskeletal/path.h"

namespace arthrosim::musculoskeletal {

struct LigamentBundle {
  BlankevoortParameters parameters;
  Path path;
};

/// A named group of bundles (e.g. "MCLs" with 6 bundles).
struct Ligament {
  std::string name;
  std::vector<LigamentBundle> bundles;
};

struct Muscle {
  std::string name;
  double max_isometric_force = 0.0;  ///< F_max [N], > 0
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
  /// Coordinates solved for (the 12 knee DOF) and prescribed (hip, ankle),
  /// indices into tree.coordinates.
  std::vector<int> free_coordinates, prescribed_coordinates;

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
  Eigen::VectorXd Q_ligaments, Q_muscles, Q_contact, Q;
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
