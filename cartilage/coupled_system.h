#pragma once
// CoupledShellSystem: several ShellModels (one per cartilage surface) solved
// as one numerics::TimeIntegrable, coupled by deformable mesh contact
// (cartilage/mesh_contact.h). Coordinates are the models' coordinates
// concatenated in the order given; every model keeps its own terms,
// constraints and mass matrix (block-diagonal), the contact pairs add forces
// and off-diagonal tangent blocks.
//
// Sparsity pattern. The tangent pattern is the block-diagonal union of the
// models' patterns plus 3 x 3 position blocks for node pairs that a contact
// could couple. The coupling part is built from the contact candidates within
// `pattern_margin_m` of the current positions; when an evaluation meets an
// active contact outside the pattern, the pattern is rebuilt around the
// current positions and pattern_revision() increases (the integrator then
// redoes its symbolic analysis; counted in statistics().pattern_rebuilds).
//
// With no contact pair the system is exactly its models side by side (same
// residuals, same tangents, bit for bit).
#include <Eigen/Core>
#include <Eigen/SparseCore>
#include <memory>
#include <string>
#include <vector>

#include "cartilage/mesh_contact.h"
#include "cartilage/shell_model.h"
#include "numerics/time_integrable.h"

namespace arthrosim::common {
class EffectLedger;
}

namespace arthrosim::cartilage {

/// Contact results of one pair at one state (contact_report()).
struct ContactPairReport {
  std::string name;
  ContactCounts counts;
  /// Nodal contact forces on each surface [N] (N_a x 3, N_b x 3): the force
  /// the other surface exerts on each node.
  common::Points3 force_a, force_b;
  /// Per-node contact pressure [Pa]: |nodal force| / nodal tributary area.
  Eigen::VectorXd pressure_a, pressure_b;
  Eigen::Vector3d total_force_a = Eigen::Vector3d::Zero();  ///< sum of force_a [N]
  Eigen::Vector3d total_force_b = Eigen::Vector3d::Zero();  ///< sum of force_b [N]
  double contact_area_m2 = 0;  ///< sum of the weights of active contacts, per side (two-pass vertex-face counts once)
};

struct CoupledSystemStatistics {
  long evaluations = 0;
  long tangent_evaluations = 0;  ///< evaluations that assembled the tangent
  long pattern_rebuilds = 0;
  double contact_time_s = 0;   ///< detection + contact forces/tangents
  double models_time_s = 0;    ///< the models' own evaluations
  double copy_time_s = 0;      ///< gathering/scattering between models and the system
  long max_active_contacts = 0;
};

class CoupledShellSystem : public numerics::TimeIntegrable {
 public:
  /// models: not owned, must outlive the system; names as given (messages).
  explicit CoupledShellSystem(std::vector<ShellModel*> models, std::vector<std::string> names);
  ~CoupledShellSystem() override;

  int num_models() const { return static_cast<int>(models_.size()); }
  ShellModel& model(int m) { return *models_[m]; }
  const ShellModel& model(int m) const { return *models_[m]; }
  const std::string& model_name(int m) const { return names_[m]; }
  /// First coordinate of model m.
  int offset(int m) const { return offsets_[m]; }
  /// Coordinates of model m from a system vector.
  Eigen::VectorXd segment(int m, const Eigen::VectorXd& x) const;

  /// Adds deformable contact between models a and b ("mesh_contact", recorded
  /// in the ledger with part = name and count = 1 if a ledger is attached).
  /// pattern_margin_m: candidates beyond max_depth included in the pattern.
  void add_contact(const std::string& name, int a, int b, const ContactOptions& options,
                   double pattern_margin_m = 0.5e-3);
  int num_contacts() const { return static_cast<int>(contacts_.size()); }
  const MeshContact& contact(int k) const { return *contacts_[k].contact; }
  /// Augmented Lagrangian multipliers of pair k (MeshContact::set_multipliers).
  void set_contact_multipliers(int k, const std::array<Eigen::VectorXd, 2>& lambda) {
    contacts_.at(k).contact->set_multipliers(lambda);
  }
  const std::array<Eigen::VectorXd, 2>& contact_multipliers(int k) const {
    return contacts_.at(k).contact->multipliers();
  }
  /// Their Uzawa update at q (MeshContact::updated_multipliers).
  std::array<Eigen::VectorXd, 2> updated_contact_multipliers(int k, const Eigen::VectorXd& q) const;
  void attach_ledger(common::EffectLedger* ledger) { ledger_ = ledger; }

  /// Contact state of pair k at (q, v) (v may be nullptr: at rest).
  ContactPairReport contact_report(int k, const Eigen::VectorXd& q, const Eigen::VectorXd* v = nullptr) const;
  const CoupledSystemStatistics& statistics() const { return stats_; }
  /// Checkpoint and resume (docs/testing.md): the coordinates the coupling
  /// pattern was last built around (the pattern depends on them, and the
  /// linear solver's ordering on the pattern), and setting them again with
  /// the statistics on a system built from the same inputs.
  const Eigen::VectorXd& pattern_coordinates() const { return pattern_q_; }
  void restore(const Eigen::VectorXd& pattern_coordinates, const CoupledSystemStatistics& statistics);

  // ---- TimeIntegrable -----------------------------------------------------
  int num_dofs() const override { return n_; }
  bool has_inertia() const override;
  bool tangent_symmetric() const override;
  void evaluate(const numerics::EvalRequest& request, Eigen::VectorXd& F, Eigen::VectorXd* Ma,
                Eigen::SparseMatrix<double>* K) override;
  const Eigen::SparseMatrix<double>& tangent_pattern() const override { return pattern_; }
  long pattern_revision() const override { return revision_; }
  const std::vector<char>& constrained() const override { return constrained_; }
  void apply_constraints(double t, Eigen::VectorXd& q) const override;
  void solve_mass(const Eigen::VectorXd& rhs, Eigen::VectorXd& a) override;
  void predict(double t0, double t1, const Eigen::VectorXd& q0, Eigen::VectorXd& q1) const override;
  void predict_extrapolated(double tp, const Eigen::VectorXd& qp, double t0, const Eigen::VectorXd& q0, double t1,
                            Eigen::VectorXd& q1) const override;
  const Eigen::VectorXd& increment_weights() const override { return weights_; }
  std::string describe_dof(int i) const override;

 private:
  struct Pair {
    std::unique_ptr<MeshContact> contact;
    int a = 0, b = 0;
    double margin = 0;
  };
  common::Points3 positions(int m, const Eigen::VectorXd& q) const;
  /// Rebuilds the pattern with the coupling candidates at q.
  void rebuild_pattern(const Eigen::VectorXd& q);
  int value_index(int row, int col) const;
  int model_of(int dof) const;

  std::vector<ShellModel*> models_;
  std::vector<std::string> names_;
  std::vector<int> offsets_;
  int n_ = 0;
  std::vector<Pair> contacts_;
  Eigen::SparseMatrix<double> pattern_;
  Eigen::VectorXd pattern_q_;  // the coordinates of the last rebuild_pattern
  std::vector<std::vector<int>> model_value_map_;  // model value index -> system value index
  long revision_ = 0;
  std::vector<char> constrained_;
  Eigen::VectorXd weights_;
  std::vector<Eigen::SparseMatrix<double>> model_K_;
  common::EffectLedger* ledger_ = nullptr;
  CoupledSystemStatistics stats_;
};

}  // namespace arthrosim::cartilage
