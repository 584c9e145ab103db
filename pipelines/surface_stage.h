#pragma once
// The deformable-surface stage (arthrosim-surface): reads a prepared model
// (docs/prepared_model.md) and a scene scenario (docs/scenes.md), builds one
// ANCF shell model per cartilage surface with exactly the scenario's effects
// (cartilage/surface_model.h), integrates it (HHT, quasi-static, or a direct
// steady-state solve) and writes the output HDF5 + XDMF sidecar through
// pipelines/surface_output.h (schema: docs/surface_output.md).
//
// Shape: surface_from_scene (the scenario's options, every cross-key rule;
// no file read) -> build (models, coupled system, integrator options from the
// prepared model and kinematics files) -> run (integrate, record).
#include <filesystem>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "cartilage/mesh_contact.h"
#include "cartilage/surface_model.h"
#include "common/options.h"
#include "numerics/hht_integrator.h"

namespace arthrosim::common {
struct Scene;
}

namespace arthrosim::pipelines {

struct StageDescriptor;
/// The surface stage's entry in the stage table (pipelines/stages.h).
StageDescriptor surface_stage_descriptor();

/// One scenario of the scene's surface block: the keys every scenario shares
/// with the block (declare_shared; a scenario may set each for itself) and
/// those only a scenario takes (declare_instance). SI units.
struct SurfaceScenarioOptions {
  // ---- shared with the surface block ----
  /// Cartilage surfaces of the prepared model simulated as shells.
  std::vector<std::string> surfaces{"femur", "tibia_medial", "tibia_lateral"};
  /// Simulated time [s]; absent: a scenario with imposed_kinematics runs for
  /// the kinematics file's duration (any other needs it).
  std::optional<double> end_time_s;
  double output_interval_s = 5 * common::units::ms;  ///< time between written frames
  /// Time step, HHT alpha, Newton tolerances, linear solver.
  numerics::IntegratorOptions integrator;
  /// Solve directly for the static equilibrium at end_time_s.
  bool steady_state = false;
  /// > 0: a time-stepping run ends once the largest weighted coordinate change
  /// over one step is at most this [m].
  double steady_state_change_m = 0;
  /// Wall time between checkpoints `<out>.checkpoint` [s] (0: after every
  /// step). A rerun of the same command continues from the last one with
  /// datasets bit-identical to an uninterrupted run
  /// (pipelines/surface_checkpoint.h).
  double checkpoint_interval_s = 60.0;
  /// Shell material, foundation, osmotic pressure (and its ramp).
  cartilage::SurfaceParameters physics;
  /// osmotic_pressure: the surfaces that carry it (empty: all simulated).
  std::vector<std::string> osmotic_surfaces;
  /// foundation_springs with k_i = K / h_i from the prepared thickness h_i.
  bool foundation_from_thickness = false;
  double matched_youngs_modulus_Pa = 10 * common::units::mpa;  ///< E of that layer
  double matched_poisson_ratio = 0.45;                          ///< nu of that layer
  enum class PeripheryNormal { kClamped, kFoundation };
  PeripheryNormal periphery_normal = PeripheryNormal::kClamped;
  double periphery_tie_N_m3 = 1000 * common::units::n_per_mm3;  ///< kFoundation's tie stiffness
  /// Pairs in mesh contact, each "a:b" (force output on b).
  std::vector<std::string> contact_pairs{"femur:tibia_medial", "femur:tibia_lateral"};
  cartilage::ContactOptions contact;
  double penetration_limit = 0.1;     ///< the seed's accuracy rule: penetration / deflection
  bool stop_on_penetration = false;   ///< penetration_action: stop (else warn)
  enum class Predictor { kRigid, kExtrapolated };
  Predictor predictor = Predictor::kExtrapolated;  ///< imposed_kinematics: Newton start of a step
  double seating_time_s = 0.02;                     ///< seating ramp before imposed kinematics
  double seating_offset_m = 1 * common::units::mm;  ///< its initial separation

  // ---- a scenario's own ----
  std::string description;
  /// Generic quad mesh (OBJ or legacy VTK, mm) simulated instead of the
  /// prepared model's surfaces; empty = none.
  std::filesystem::path mesh;
  std::vector<double> fixed_box_m;      ///< [xmin, ymin, zmin, xmax, ymax, zmax]; empty = none
  std::vector<double> load_box_m;       ///< same; empty = none
  std::vector<double> point_load_N;     ///< [fx, fy, fz]; empty = none
  std::optional<double> pressure_Pa;    ///< on the mid-surface of `mesh`
  std::vector<double> displaced_box_m;  ///< same box form; empty = none
  std::vector<double> displacement_m;   ///< [ux, uy, uz]; empty = none
  /// Named node sets, masked constraints and loads of `mesh`, one text item
  /// each (grammar: cartilage/shell_scene.h); empty = none.
  std::vector<std::string> node_sets, constraints, loads, histories;
  std::vector<std::string> effects;     ///< the scenario's effects

  void declare_shared(common::OptionVisitor& v);
  void declare_instance(common::OptionVisitor& v);
  void declare(common::OptionVisitor& v) {
    declare_shared(v);
    declare_instance(v);
  }
};

/// One scenario of a scene, checked: every rule between its keys that needs
/// no file (surface_from_scene). Pure data.
struct SurfaceScenarioConfig {
  std::filesystem::path scene_file;
  std::string name;  ///< the scenario
  int line = 0;      ///< where it is written in the scene
  int surfaces_line = 0;  ///< where `surfaces` is written (0: the default)
  std::vector<std::string> effects;
  SurfaceScenarioOptions options;
  std::string canonical_options;  ///< the scenario's options as the runner hashes them
  bool moving = false;        ///< imposed_kinematics
  bool generic = false;       ///< a generic `mesh` instead of the prepared model
  bool contact = false;       ///< mesh_contact
  bool steady = false;        ///< steady_state
  bool quasi_static = false;  ///< steady_state, or no inertia
  std::vector<std::string> surfaces;  ///< prepared surfaces simulated (empty for a generic mesh)
  /// mesh_contact: pairs as indices into `surfaces`, and as written ("a:b").
  std::vector<std::pair<int, int>> contact_pairs;
  std::vector<std::string> contact_pair_names;
  /// Generic mesh: node_sets, constraints and loads parsed (sets referenced exist).
  std::vector<cartilage::NodeSetDefinition> node_sets;
  std::vector<cartilage::ConstraintDefinition> constraints;
  std::vector<cartilage::LoadDefinition> loads;
  std::vector<cartilage::HistoryDefinition> histories;
};

/// The scenario `scenario` of `scene` ("" = the scene's only one) with every
/// cross-key rule checked (osmotic_ramp_s and imposed_kinematics, generic
/// effects and their keys, contact pairs among the surfaces, ...). Reads no
/// file; InputError with the scene's line otherwise.
SurfaceScenarioConfig surface_from_scene(const common::Scene& scene, const std::string& scenario);

struct SurfaceStageOptions {
  std::string prepared;    ///< prepared-model HDF5
  std::string kinematics;  ///< kinematics HDF5 ("" = none)
  std::string scene;       ///< scene YAML
  std::string scenario;    ///< scenario name ("" = the scene's only scenario)
  std::string out;         ///< output HDF5; the XDMF sidecar gets the same stem
  bool progress = true;    ///< progress lines on stderr
  /// Go on with an incomplete kinematics file (common/file_check.h); the
  /// output then records it in its root attribute partial_input.
  bool allow_partial = false;
  std::vector<std::string> argv;  ///< command line, for the run metadata
};

enum class SurfaceStageStatus { kCompleted, kFailed };

/// What one surface ended with (last written frame).
struct SurfaceSummary {
  std::string name;
  int nodes = 0, elements = 0;
  double max_deflection_m = 0;  ///< largest |deflection| over the run (signed value of that node)
  double max_deflection_time_s = 0;  ///< when it occurred
  double e1_min = 0, e1_max = 0;  ///< range of the first principal strain over the run
  double e2_min = 0;              ///< smallest second principal strain over the run
  double final_residual_N = 0;    ///< residual norm of the last accepted step
  double residual_tolerance_N = 0;  ///< the tolerance that step met
};

struct SurfaceStageResult {
  SurfaceStageStatus status = SurfaceStageStatus::kFailed;
  std::string scenario;
  std::vector<SurfaceSummary> surfaces;
  long steps = 0, newton_iterations = 0, rejected_steps = 0, factorizations = 0, pattern_changes = 0;
  int frames = 0;
  double wall_s = 0, assembly_s = 0, contact_s = 0, factorization_s = 0, solve_s = 0;
  /// Parts of assembly_s (wall): element loops and their summation, all
  /// surface terms together (elements included), surface <-> system copies.
  double elements_s = 0, element_scatter_s = 0, surfaces_s = 0, coupling_copy_s = 0;
  long evaluations = 0, tangent_evaluations = 0;  ///< residual evaluations, those with a tangent
  double final_residual_N = 0, residual_tolerance_N = 0;  ///< last accepted step
  // mesh_contact only:
  double max_penetration_m = 0;        ///< largest interpenetration of any step
  long contact_steps = 0;              ///< steps with at least one active contact
  int checkpoints = 0;                 ///< checkpoints written by this run
  long active_contacts_sum = 0;        ///< sum over steps of active contacts
  long penetration_warnings = 0;       ///< steps breaking the accuracy rule
  double worst_penetration_ratio = 0;  ///< largest penetration / deflection of those
  /// The same over unfaded contacts only (away from rims; reported, not enforced).
  long unfaded_penetration_warnings = 0;
  double worst_unfaded_penetration_ratio = 0;
  // steady_state_change_mm > 0 only:
  bool steady_state_stop = false;      ///< the run could stop at the steady state
  bool steady_state_reached = false;   ///< it did (false: end_time_s came first)
  double stop_time_s = 0;              ///< time of the last step
  double last_change_m = 0;            ///< largest weighted coordinate change over that step
};

/// Runs the stage. Throws common::InputError on bad input (naming file and
/// dataset or scene line) and common::NumericalError when the solver gives
/// up (after the halvings); frames written until then stay in the file.
SurfaceStageResult run_surface_stage(const SurfaceStageOptions& options);

}  // namespace arthrosim::pipelines
