#pragma once
// ShellModel: a mesh of ANCF shell elements (shell_element.h) and the list of
// terms a scene asks for, in the MFEM spirit: each physical effect is one term
// object that adds its generalised force and tangent. Each term class lives in
// its own file, cartilage/terms/<name>.{h,cc}, with its registration
// (cartilage/surface_terms.h); register_term adds one, the add_* methods are
// thin wrappers over the bundled terms' factories, and built_terms() lists
// what was built (tests assert that nothing else exists).
//
// Coordinates: node i owns q[6i .. 6i+2] = r_i (position, m, world) and
// q[6i+3 .. 6i+5] = d_i (transverse gradient dr/dz, dimensionless).
//
// Residual convention (Ma + F = 0 at equilibrium / in motion):
//   F(q, v, t) = f_int(q) + f_damp(q, v, t) - f_ext(q, t).
//
// Constraints (fixed nodes, periphery fixed to a bone, prescribed motion) are
// imposed by ELIMINATION: constrained coordinates take their prescribed
// values before each Newton solve, and their rows/columns of the Newton matrix
// are replaced by the identity (zero right-hand side). No penalty parameter.
// A constraint may hold components in a local frame (NodeConstraint::frames,
// e.g. an oblique symmetry plane): the standard skew boundary condition. For
// each node group (position r_i or director d_i) that a local-frame
// constraint touches, the held directions a_k (world unit vectors, from every
// constraint on that group) span a subspace with orthogonal projector P; the
// Newton system is taken in the rotated basis with those rows/columns
// eliminated, written back in world coordinates: F -> Q F, M a -> Q M a,
// K -> Q K Q + s P with Q = I - P, s the largest diagonal entry of the
// group's block of K (so that P dq = 0 and Q K Q dq = -Q F). Such
// groups are not listed in constrained(); apply_constraints sets a_k . x to
// the prescribed values by the smallest change of x.
//
// Ownership: the model owns its elements and terms; term references returned
// by add_* stay valid for the model's lifetime.
#include <Eigen/Core>
#include <Eigen/Geometry>
#include <Eigen/SparseCore>
#include <array>
#include <functional>
#include <memory>
#include <string>
#include <vector>

#include "cartilage/shell_element.h"
#include "numerics/time_integrable.h"
#include "common/mesh.h"

namespace arthrosim::common {
class EffectLedger;
}
namespace arthrosim::numerics {
class SparseDirectSolver;
}

namespace arthrosim::cartilage {

class ShellModel;

/// Rigid motion of a bone: pose X_WB(t) and its spatial velocity
/// (angular w_W, linear velocity of the bone origin v_WBo_W), both at time t.
/// The reference configuration of the shell corresponds to pose(0).
struct BoneMotion {
  std::function<Eigen::Isometry3d(double)> pose;                      ///< X_WB(t)
  std::function<Eigen::Matrix<double, 6, 1>(double)> spatial_velocity;  ///< [w_W; v_WBo_W]
  bool at_rest = false;  ///< true only for fixed(): lets terms report symmetric tangents
  /// A bone at rest at the identity pose.
  static BoneMotion fixed();
};

/// How foundation_springs integrates the foundation over the surface:
/// springs at the nodes with their nodal areas (the seed's elements), or the
/// element-consistent (Galerkin) integral (ShellModel::add_foundation_springs).
enum class FoundationIntegration { kNodal, kConsistent };

/// Writes access to the tangent values in the model's fixed pattern.
class TangentAssembler {
 public:
  TangentAssembler(const ShellModel& model, Eigen::SparseMatrix<double>& K) : model_(model), K_(K) {}
  /// Adds a 24x24 element block (element coordinate order).
  void add_element(int e, const Matrix24& Ke);
  /// Adds a 3x3 block coupling coordinates [6a+oa, 6a+oa+3) and [6b+ob, 6b+ob+3)
  /// (a, b must share an element or be equal; oa, ob in {0, 3}).
  void add_block3(int a, int oa, int b, int ob, const Eigen::Matrix3d& B);
  /// The same for corners a, b (0..3) of element e, through the element's
  /// cached value indices (no pattern search).
  void add_element_block3(int e, int a, int oa, int b, int ob, const Eigen::Matrix3d& B);
  Eigen::SparseMatrix<double>& matrix() { return K_; }

 private:
  const ShellModel& model_;
  Eigen::SparseMatrix<double>& K_;
};

struct TermContext {
  double t = 0;
  const Eigen::VectorXd& q;
  const Eigen::VectorXd& v;  ///< zero vector in quasi-static evaluations
  const Eigen::VectorXd& a;  ///< zero vector when there is no inertia
  double kq = 1, kv = 0, ka = 0;  ///< tangent factors (force_scale already applied)
};

/// One physical effect. add() adds the term's generalised force to F (or M a
/// to Ma for inertia) and, if K != nullptr, its tangent contribution.
class ShellTerm {
 public:
  explicit ShellTerm(std::string name) : name_(std::move(name)) {}
  virtual ~ShellTerm() = default;
  const std::string& name() const { return name_; }
  virtual bool symmetric() const { return true; }
  virtual bool inertial() const { return false; }
  virtual void add(const TermContext& ctx, Eigen::VectorXd& F, TangentAssembler* K) const = 0;

 private:
  std::string name_;
};

/// Fixed / prescribed coordinates of a node set. `value(t, node, q6)` writes
/// the prescribed 6 coordinates of `node` at time t (only the masked entries
/// are used). Registered in built_terms() under its name.
struct NodeConstraint {
  std::string name;
  std::vector<int> nodes;
  std::array<bool, 6> mask{};  ///< which of r_x, r_y, r_z, d_x, d_y, d_z
  /// Per node (same order as `nodes`) instead of `mask`, when not empty.
  std::vector<std::array<bool, 6>> node_masks;
  std::function<void(double, int, Eigen::Matrix<double, 6, 1>&)> value;
  /// Local frames R_WL (columns: the local axes in world) in which the mask
  /// is read, for positions and directors alike: empty = world frame; one =
  /// the same for every node; else one per node (same order as `nodes`).
  /// With a frame, `value` still writes world coordinates; the constraint
  /// holds their masked local components.
  std::vector<Eigen::Matrix3d> frames;
};

struct ShellModelStatistics {
  long evaluations = 0;       ///< residual (+tangent) evaluations
  long tangent_evaluations = 0;
  double element_time_s = 0;  ///< wall time in element loops (parallel part)
  double scatter_time_s = 0;  ///< wall time summing element results (serial)
};

class ShellModel : public numerics::TimeIntegrable {
 public:
  /// mesh: nodes [m] and counter-clockwise quads; directors: per-node reference
  /// transverse gradient (N x 3, normalised here; must lie on the side of the
  /// quad normals); thickness_m: per-node thickness (N) [m].
  ShellModel(const common::QuadMesh& mesh, const common::Points3& directors,
             const Eigen::VectorXd& thickness_m, const ShellMaterial& material);
  ~ShellModel() override;

  int num_nodes() const { return num_nodes_; }
  int num_elements() const { return static_cast<int>(elements_.size()); }
  const ShellElement& element(int e) const { return *elements_[e]; }
  const common::Quads& quads() const { return quads_; }
  const Eigen::VectorXd& reference_state() const { return q0_; }
  /// int N_i dA over the reference mid-surface [m^2] per node.
  const Eigen::VectorXd& nodal_areas() const { return nodal_area_; }
  Eigen::Vector3d reference_position(int i) const { return q0_.segment<3>(6 * i); }
  Eigen::Vector3d reference_director(int i) const { return q0_.segment<3>(6 * i + 3); }
  /// Nodes on the open boundary (edges used by one quad), sorted.
  std::vector<int> boundary_nodes() const;

  // ---- Bundled terms (cartilage/terms/<name>.cc) ----------------------------
  /// Elastic internal forces of all elements (parallel, deterministic).
  ShellTerm& add_internal_forces();
  /// Compressive-only springs from every node to its anchor on the bone along
  /// the reference transverse direction n_i: deflection
  ///   delta_i = n_i(t) . (X_WB(t) X_WB(0)^-1 r_i0 - r_i),
  /// force k A_i max(delta_i, 0) n_i(t) on the node (A_i = nodal area). The rest
  /// length (reference projection onto the bone) cancels out of delta_i.
  /// At delta_i = 0 the spring counts as engaged in the tangent (zero force).
  /// k_N_m3: foundation modulus [N/m^3] (seed 002: 0.7 N/mm^3 = 7e8 N/m^3).
  /// compressive_only = false makes the springs act in tension too (tests
  /// of the elastic-foundation closed forms).
  ///
  /// integration = kConsistent integrates the same foundation over each
  /// element instead (Galerkin): the deflection delta_g = sum_k N_k delta_k
  /// and modulus k_g = sum_k N_k k_k at the element's 2x2 mid-surface Gauss
  /// points, energy sum_g k_g dA_g max(delta_g, 0)^2 / 2 (compressive-only
  /// per Gauss point), which couples the four nodes of an element. Under a
  /// uniform deflection both give the same force; where the deflection
  /// varies over a few elements (a foundation stiff enough that the shell's
  /// bending length lambda^-1 = (4 D / k)^(1/4) spans 1-2 elements) the
  /// nodal springs let the shell spread a load wider (docs/contact.md).
  ShellTerm& add_foundation_springs(double k_N_m3, BoneMotion bone = BoneMotion::fixed(),
                                    bool compressive_only = true,
                                    FoundationIntegration integration = FoundationIntegration::kNodal);
  /// As above with a modulus per node [N/m^3] (e.g. k_i = K / h_i from the
  /// local cartilage thickness h_i, the elastic-foundation layer modulus).
  ShellTerm& add_foundation_springs(const Eigen::VectorXd& k_per_node_N_m3, BoneMotion bone,
                                    bool compressive_only = true,
                                    FoundationIntegration integration = FoundationIntegration::kNodal);
  /// Matching dampers: force c A_i d(delta_i)/dt n_i(t). When
  /// compressive_only (the seed's spring-dampers are compressive elements)
  /// it is gated by the compression: H(delta_i / gate_m) with H the
  /// smoothstep (0 for delta <= 0, 1 for delta >= gate_m), so that the force
  /// stays continuous where delta changes sign. c_N_s_m3 [N s/m^3].
  ShellTerm& add_foundation_damping(double c_N_s_m3, BoneMotion bone = BoneMotion::fixed(),
                                    bool compressive_only = true, double gate_m = 1e-6);
  /// Pressure p(t) [Pa] on the face zeta = face_zeta (-1 inner, 0 mid, +1
  /// outer) as a follower load: traction p n on the deformed face, n the unit
  /// normal on the director side (p > 0 pushes the face along +n). Its
  /// tangent is not symmetric. `name` is e.g. "osmotic_pressure" (seed 002:
  /// 0.2 MPa on the internal face, face_zeta = -1) or "pressure".
  ShellTerm& add_pressure(const std::string& name, double face_zeta, std::function<double(double)> p_Pa);
  /// Nodal point loads [N] on positions, scaled by scale(t).
  ShellTerm& add_point_loads(const std::string& name, std::vector<std::pair<int, Eigen::Vector3d>> loads,
                             std::function<double(double)> scale);
  /// Conservative couple on transverse gradients: generalised force
  /// M_i(t) (e x d_i)/|d_i,perp|^2 on d_i (potential -M_i theta_i, theta_i the
  /// angle of d_i about the fixed unit axis e), the energy equivalent of a
  /// linear through-thickness end traction following the fibre; e.g. the end
  /// moment of a cantilever. moments: (node, M_i [N m]) scaled by scale(t).
  ShellTerm& add_director_moments(const std::string& name, const Eigen::Vector3d& axis,
                                  std::vector<std::pair<int, double>> moments,
                                  std::function<double(double)> scale);
  /// Inertia M a with the constant consistent mass matrix (assembled here,
  /// once; its Cholesky factor is computed on the first solve_mass call).
  ShellTerm& add_inertia();

  // ---- Constraints (elimination) -----------------------------------------
  /// Fixes the masked coordinates of `nodes` at their reference values.
  void fix_nodes(const std::string& name, const std::vector<int>& nodes, std::array<bool, 6> mask);
  /// "periphery_fixed": boundary nodes (all 6 coordinates) move rigidly with
  /// the bone: r = X_WB(t) X_WB(0)^-1 r0, d = R(t) R(0)^T d0.
  void add_periphery_fixed(BoneMotion bone = BoneMotion::fixed());
  /// "periphery_fixed" with the normal free: boundary nodes tied to the bone
  /// in their tangent plane only (penalty k_t A_i (I - n n^T), n the
  /// bone-carried reference transverse direction; k_t [N/m^3] > 0), so that
  /// along the normal they rest on the foundation like interior nodes; the
  /// directors are free. For contact zones that reach the rim of a surface
  /// (docs/contact.md). Recorded as periphery_fixed.
  ShellTerm& add_periphery_tangential(double k_t_N_m3, BoneMotion bone = BoneMotion::fixed());
  /// General prescribed motion.
  void add_constraint(NodeConstraint c);

  /// Step predictor (TimeIntegrable::predict): the surface carried rigidly
  /// by `bone` from t0 to t1 (positions r -> T r, directors d -> R d with
  /// T = X_WB(t1) X_WB(t0)^-1), so that Newton starts from the bone's motion
  /// and only has to find the deformation change.
  void set_motion_predictor(BoneMotion bone) { predictor_ = std::move(bone); has_predictor_ = true; }
  void predict(double t0, double t1, const Eigen::VectorXd& q0, Eigen::VectorXd& q1) const override;
  /// Extrapolating predictor: the deformation change of the step before, seen
  /// from the bone (qp carried rigidly from tp to t0, subtracted from q0),
  /// scaled by (t1 - t0)/(t0 - tp) and added to q0, all then carried by the
  /// bone from t0 to t1. Without a motion predictor: q0 + s (q0 - qp).
  void predict_extrapolated(double tp, const Eigen::VectorXd& qp, double t0, const Eigen::VectorXd& q0, double t1,
                            Eigen::VectorXd& q1) const override;

  /// Records every later-built term whose name is in the scene vocabulary
  /// (common/effects.h: foundation_springs, foundation_damping,
  /// osmotic_pressure, periphery_fixed, inertia, ...) into `ledger`, with
  /// part = the mesh name and count = springs/dampers (nodes), loaded
  /// elements, constrained nodes or mass elements. Terms outside the
  /// vocabulary (internal_forces, generic test loads) appear only in
  /// built_terms(). The ledger must outlive the model; nullptr detaches.
  void attach_ledger(common::EffectLedger* ledger) { ledger_ = ledger; }

  /// Names of the terms and constraints built so far, in creation order.
  const std::vector<std::string>& built_terms() const { return built_; }
  const std::vector<std::unique_ptr<ShellTerm>>& terms() const { return terms_; }
  const ShellModelStatistics& statistics() const { return stats_; }

  // ---- TimeIntegrable -----------------------------------------------------
  int num_dofs() const override { return 6 * num_nodes_; }
  bool has_inertia() const override { return has_inertia_; }
  bool tangent_symmetric() const override;
  void evaluate(const numerics::EvalRequest& request, Eigen::VectorXd& F, Eigen::VectorXd* Ma,
                Eigen::SparseMatrix<double>* K) override;
  const Eigen::SparseMatrix<double>& tangent_pattern() const override { return pattern_; }
  const std::vector<char>& constrained() const override { return constrained_; }
  void apply_constraints(double t, Eigen::VectorXd& q) const override;
  /// F (and K) of the terms without the local-frame projection of evaluate()
  /// (identical to evaluate() when no constraint has a frame): the forces
  /// whose constrained components are the reactions.
  void evaluate_unprojected(const numerics::EvalRequest& request, Eigen::VectorXd& F, Eigen::SparseMatrix<double>* K);
  /// True when a constraint holds components in a local frame.
  bool has_local_frames() const { return !skew_groups_.empty(); }
  void solve_mass(const Eigen::VectorXd& rhs, Eigen::VectorXd& a) override;
  const Eigen::VectorXd& increment_weights() const override { return weights_; }
  std::string describe_dof(int i) const override;

  // ---- Pattern access (for TangentAssembler and terms) ---------------------
  /// Value index in the pattern of entry (row, col); -1 if not in the pattern.
  int value_index(int row, int col) const;
  /// 576 value indices of element e (row-major over element coordinates).
  const int* element_value_indices(int e) const { return &element_index_[576 * static_cast<size_t>(e)]; }
  /// Element coordinate vector (24) gathered from a global vector.
  Vector24 gather(int e, const Eigen::VectorXd& x) const;
  /// Global coordinate index of element e's local coordinate l (0..23).
  int global_index(int e, int l) const { return 6 * quads_(e, l / 6) + l % 6; }
  /// Sparse mass matrix (empty until add_inertia()).
  const Eigen::SparseMatrix<double>& mass_matrix() const { return mass_; }
  ShellModelStatistics& mutable_statistics() { return stats_; }

  /// Adds a term (a ShellTerm of a registered surface term,
  /// cartilage/surface_terms.h) and records `count` instances of its name in
  /// the ledger when the name is an effect. The add_* methods use it.
  ShellTerm& register_term(std::unique_ptr<ShellTerm> term, long count);

 private:
  void record(const std::string& name, long count);
  void build_pattern();
  void assemble(const numerics::EvalRequest& request, Eigen::VectorXd& F, Eigen::VectorXd* Ma,
                Eigen::SparseMatrix<double>* K);
  /// Recomputes constrained_ and the local-frame groups from constraints_.
  void index_constraints();
  /// x -> Q x on the local-frame groups; A -> Q A Q + P (values in A's pattern).
  void project_vector(Eigen::VectorXd& x) const;
  void project_matrix(Eigen::SparseMatrix<double>& A) const;

  int num_nodes_ = 0;
  common::Quads quads_;
  std::vector<std::unique_ptr<ShellElement>> elements_;
  Eigen::VectorXd q0_, nodal_area_, weights_;
  Eigen::SparseMatrix<double> pattern_, mass_;
  std::vector<int> element_index_;
  std::vector<std::unique_ptr<ShellTerm>> terms_;
  std::vector<NodeConstraint> constraints_;
  std::vector<char> constrained_;
  /// A held direction of a local-frame group: constraint, position in its
  /// node list, coordinate 0..5 (its group offset), world unit vector.
  struct HeldDirection {
    int constraint, index, coordinate;
    Eigen::Vector3d a;
  };
  struct SkewGroup {
    int group;  ///< coordinates [3 group, 3 group + 3)
    Eigen::Matrix3d P;
    std::vector<HeldDirection> held;
  };
  std::vector<SkewGroup> skew_groups_;
  std::vector<std::string> built_;
  bool has_inertia_ = false;
  std::string part_;
  common::EffectLedger* ledger_ = nullptr;
  BoneMotion predictor_;
  bool has_predictor_ = false;
  std::unique_ptr<numerics::SparseDirectSolver> mass_solver_;
  ShellModelStatistics stats_;
};

/// Reference transverse directions: area-weighted unit normals of the quads
/// around each node (N x 3), for meshes without given directors.
common::Points3 quad_mesh_vertex_normals(const common::QuadMesh& mesh);

}  // namespace arthrosim::cartilage
