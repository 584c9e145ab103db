#pragma once
// COMAK (Concurrent Optimization of Muscle Activations and Kinematics; Smith
// et al. 2016; seeds/002_3ffcc11eb7a447d9.txt, "Tibiofemoral kinematics during
// walking were predicted using ... COMAK"), solved per frame as ONE nonlinear
// program by Ipopt (no linearised outer loop, no silent fallback; see
// /work/shared/references.md for what the reference implementation does).
//
// Per frame, with the knee flexion q_f, the hip and ankle angles prescribed
// from the trial and the external load (F_ext, M_ext) on the tibia:
//
//   min_{a, s, e}  sum_i w_i V_i a_i^2  +  sum_j w_r (e_j / e_ref)^2
//   s.t.  c_k = S_k [ Q_k(q_f, s, a) + Q_ext,k(q_f, s) + e_k ] = 0,  k = the 12
//         free knee coordinates (flexion, 5 tibial, 6 patellar);
//         a_min <= a_i <= 1,  lower_j <= s_j <= upper_j (URDF limits).
//
//   a   muscle activations (force a_i F_max,i along the path, as COMAK);
//   s   the 11 secondary coordinates (all free coordinates except flexion);
//   e   reserve actuators on the secondary coordinates (only with
//       options.reserve_actuators; N or N m; e_k = 0 for flexion, whose
//       equation the muscles balance);
//   Q   generalized forces of ligaments, muscles and elastic-foundation
//       contact (model.h);
//   Q_ext = J_T(o_T)^T R_WT F_ext_T + J_rot,T^T R_WT M_ext_T: the external
//       load given in the tibia frame T about the tibia origin (the knee
//       joint centre of the model at q = 0; it coincides with the tibia frame
//       of knee_loads.h for a right knee) follows the tibia (applied at its
//       origin, a material point, rotating with it);
//   V_i muscle-volume weight F_max,i l_ref,i / 350 kPa [m^3] (COMAK's V = F_max
//       l_opt / sigma with sigma = 350 kPa). The model files carry no optimal
//       fibre length, so l_ref,i = the muscle's path length at q = 0 stands in
//       for l_opt (a documented stand-in; it overweights long-tendon muscles
//       such as the gastrocnemii relative to true fibre volume);
//   w_i per-muscle weights (default 1).
//
// Scaling (docs/comak.md): moment rows are divided by a length L
// (S_k = 1/L for revolute, 1 for prismatic rows, L = length_scale = 0.03 m),
// so every constraint is a force-equivalent in N and one tolerance in N
// covers both (moment tolerance = force tolerance x L). Translations are
// handed to Ipopt as s/L (Ipopt x_scaling), so 1 unit is 30 mm, comparable to
// 1 rad of rotation. The objective is divided by sum_i w_i V_i (so a
// uniform activation of 1 costs 1).
//
// Derivatives: dc/da = S F_max,i r_i(q) (exact: the activation part is
// linear); dc/ds from the model's dQ/dq (central differences,
// evaluate_jacobian) plus dQ_ext/ds by central differences of the kinematics
// (checked against finite differences of c in tests/musculoskeletal/
// comak_test.cc); dc/de = S (exact). Hessian: Ipopt's limited-memory
// quasi-Newton (L-BFGS) approximation of the Lagrangian's Hessian.
//
// Ankle equilibrium (ComakOptions::ankle_equilibrium, off by default): a
// 13th row, the moment balance of the foot about the ankle axis under the
// muscles that span the ankle and the foot's external load from the inverse
// dynamics (ground reaction, weight and inertia of the foot). Without it the
// ankle moment is internal to the shank+foot load and nothing asks the
// gastrocnemii for ankle work (docs/comak.md).
//
// Body inertia (ComakOptions::body_inertia, off by default): without it the
// tibia's weight and d'Alembert force are those of the shank segment of the
// inverse dynamics (knee_loads.h; anthropometric COM and inertia, tibia
// moving with the trial's rigid leg chain), inside F_ext/M_ext, and the
// patella's are neglected. With it, the external load is the FOOT's load
// moved to the knee centre (the shank's terms taken out, so nothing counts
// twice) and the tibia and patella bodies of the knee model get their own
// weight and d'Alembert forces from their URDF masses, centres of mass and
// inertias, moving with the model's kinematics: the femur frame's lab motion
// from the trial's leg chain, the prescribed flexion's velocity and
// acceleration from the trial, the secondary coordinates at zero rate
// (add_inertial_forces, kinematics.h; docs/comak.md).
//
// Never silently: each frame reports Ipopt's status, iterations, objective,
// equilibrium residuals (N, N m) and wall time. A frame counts as converged
// only if Ipopt reports success (or "acceptable") AND the residuals are below
// the tolerances. Attempt 1 starts from the previous frame within moving
// limits (step control: see move_limits_first). A failed frame is retried (ComakOptions::retries): attempt 2
// starts from the passive settle at the frame's flexion with activations at
// a_min; attempt 3 starts from the warm start with Ipopt's adaptive barrier
// update and twice the iteration limit; attempt 4 starts from the passive
// settle of the neutral pose (independent of the given start) with step
// control: rounds of Ipopt solves within moving limits on the secondary
// coordinates, each centred where the last one ended. A frame whose first attempt converged
// is, with ComakOptions::second_start (default), solved a second time from the
// passive settle of the neutral pose and the lower converged objective kept.
// If all fail, the frame is marked
// failed (its last iterate is reported as such, never replaced). A non-finite
// value stops the run with a NumericalError naming the frame.
#include <Eigen/Core>
#include <functional>
#include <map>
#include <string>
#include <utility>
#include <vector>

#include "common/error.h"
#include "common/options.h"
#include "musculoskeletal/gait_trial.h"
#include "musculoskeletal/knee_loads.h"
#include "musculoskeletal/model.h"
#include "musculoskeletal/model_loads.h"
#include "musculoskeletal/settle.h"

namespace arthrosim::musculoskeletal {

struct ComakOptions {
  /// Lower bound of every activation [-], 0 <= a_min < 1 (COMAK: 0.01).
  double activation_min = 0.01;
  /// Per-muscle weights w_i by muscle name [-], > 0 (absent: 1).
  std::map<std::string, double> muscle_weights;
  /// Muscle stress of the volume weight V = F_max l_ref / sigma [Pa].
  double muscle_stress = 350e3;
  /// Reserve actuators on the 11 secondary coordinates (off by default).
  bool reserve_actuators = false;
  /// Reserve cost w_r (e / e_ref)^2, relative to a fully active muscle of
  /// average volume weight [-] (COMAK: 1000).
  double reserve_weight = 1000.0;
  /// e_ref [N for translations, N m for rotations].
  double reserve_reference = 1.0;
  /// Equilibrium tolerance of the force rows [N]; moment rows use
  /// force_tolerance x length_scale [N m]. Ipopt's constr_viol_tol.
  double force_tolerance = 0.1;
  /// L of the scaling [m] (see header).
  double length_scale = 0.03;
  /// Ipopt's relative tolerance 'tol' (scaled NLP) [-].
  double ipopt_tolerance = 1e-4;
  /// Ipopt's 'acceptable_tol' [-] and 'acceptable_iter' (consecutive
  /// acceptable iterates that stop the solve). The faceted contact makes the
  /// Lagrangian's gradient jump by ~1e-2 (scaled) between neighbouring
  /// iterates, so tol is rarely reached; an acceptable stop is reported as
  /// such (Ipopt status 1). Measured on the coarse model, frames 5-20 of the
  /// bundled trial: objectives within 0.1 % of a tol = 1e-8 solve (docs/comak.md).
  double ipopt_acceptable_tolerance = 1e-2;
  int acceptable_iterations = 5;
  /// Ipopt iteration limit per attempt.
  int max_iterations = 300;
  /// Ipopt print level (0 = silent, 5 = Ipopt's default).
  int print_level = 0;
  /// Ankle equilibrium (off by default): adds a 13th constraint row, the
  /// moment balance of the foot about the model's ankle axis,
  ///   Q_ankle(q, a) + n_A . (M_foot_T + (c_leg - c_A) x F_foot_T) = 0,
  /// balanced by every muscle that spans the ankle (the gastrocnemii of the
  /// knee model, plus uniarticular ankle muscles such as the stand-ins of
  /// ankle_muscles.h, which the model must then contain). n_A, c_A: the
  /// ankle joint's axis and origin in the tibia frame (the joint's parent
  /// must be the tibia); c_leg, F_foot_T, M_foot_T: the inverse dynamics of
  /// the foot (knee_loads.h), so a trial that gives knee loads directly
  /// cannot be used. The row is scaled like the other moment rows.
  bool ankle_equilibrium = false;
  /// Hip equilibrium (off by default; a model with its own leg only,
  /// ComakProblem::model_dynamics): three more rows, the leg's moment balance
  /// about the hip joint's three axes under the muscles and ligaments that
  /// span the hip and the trial's forces and the weight and d'Alembert forces
  /// of every leg body (OpenSim-JAM's primary hip coordinates; the model must
  /// carry the hip muscles: `arthrosim import-osim --muscles leg`).
  bool hip_equilibrium = false;
  /// Weight and d'Alembert forces of the tibia and patella bodies (off by
  /// default; see the header): needs the foot load and the femur's lab motion
  /// of the inverse dynamics (ComakFrameInput::has_foot_load and
  /// has_femur_motion; comak_frame_inputs with a LegModel gives both).
  bool body_inertia = false;
  /// Warm-start attempt 1 of each frame with the previous converged frame's
  /// multipliers too (Ipopt warm_start_init_point), not only its point.
  bool warm_start_multipliers = true;
  /// Retry attempts after a failed first attempt: 0, 1 (from the settle
  /// pose), 2 (also: adaptive barrier, doubled iteration limit) or 3 (also:
  /// moving limits from the passive settle of the neutral pose, below).
  int retries = 3;
  /// Step control by moving limits (docs/comak.md, "Step control"): each
  /// round limits every secondary coordinate to +- move_limit_m
  /// (translations) or move_limit_rad (rotations) around the round's start;
  /// at most move_limit_rounds rounds of at most min(move_limit_iterations,
  /// max_iterations) Ipopt iterations each. Used by attempt 4 and the
  /// re-solve of a solution on a joint limit (retries 3), and with
  /// move_limits_first by attempt 1 and the second start. Measured on 120 deg
  /// under 1 BW: 1 mm / 1 deg does not converge in 30 rounds, 3 and 5 do;
  /// 100 iterations per round take about 2/3 of the time of 300.
  ///
  /// move_limits_first: attempt 1 (the warm start from the previous frame)
  /// and the second start also within moving limits, so a frame stays on the
  /// branch its predecessor was on unless the second start finds a lower
  /// objective. Without it, measured on the bundled trial with AVX2 kernels,
  /// Ipopt's first steps flipped the patella to about 135 deg of patellar
  /// flexion at 8-46 deg of knee flexion (frames 92-107) and threw frame 64
  /// 18 mm off its neighbours.
  bool move_limits_first = true;
  double move_limit_m = 3e-3;
  double move_limit_rad = 3.0 * 3.14159265358979323846 / 180.0;
  int move_limit_rounds = 30;
  int move_limit_iterations = 100;
  /// The second start's moving limits are this many times move_limit_m /
  /// move_limit_rad: it starts from the unloaded neutral settle, far from a
  /// loaded frame's solution. Measured on the demo's stage 1 (AVX2 kernels,
  /// docs/comak.md): 1 -> 129 s and 33,634 Ipopt iterations, 3 -> 37.5 s and
  /// 10,016, the same largest jumps between frames, objective sum 0.06 %
  /// higher.
  double second_start_move_limit_scale = 3.0;
  /// Also solve every frame whose first attempt converged from the passive
  /// settle of the neutral pose at its flexion (activations at a_min; where a
  /// run's first frame starts) and keep the converged
  /// solution with the lower objective: the problem has local optima (the
  /// knee's laxity, the faceted contact), and a warm start carries the
  /// previous frame's branch forward.
  bool second_start = true;
  /// The model's coordinate dampers (Model::coordinate_springs' viscosity,
  /// OpenSim's SpringGeneralizedForce) act on the secondary coordinates with
  /// the speed (s - s_prev) / dt from the previous converged frame (dt the
  /// time between them) and on the prescribed ones with the trial's speed
  /// (docs/comak.md, "Coordinate dampers"). Without it the frame is static.
  bool coordinate_damping = true;
  /// Force terms and the finite-difference step of dQ/dq.
  ForceOptions forces;
  /// Passive settle of the first frame and of retry 1 (its `fixed` is set
  /// by the solver to the flexion).
  SettleOptions settle;

  /// Scene keys of the comak block (common/options.h; comak_options.cc):
  /// ipopt_tolerance, ipopt_acceptable_iterations, ipopt_max_iterations,
  /// activation_min, reserve_actuators, ankle_equilibrium, hip_equilibrium,
  /// coordinate_damping, body_inertia, second_start.
  void declare(common::OptionVisitor& v);
};

/// Inputs of one frame.
struct ComakFrameInput {
  int index = 0;                 ///< frame number in the trial (for messages)
  double time = 0.0;             ///< [s]
  double knee_flexion = 0.0;     ///< [rad], prescribed
  Eigen::Vector3d hip_angles = Eigen::Vector3d::Zero();  ///< flexion, adduction, rotation [rad]
  double ankle_flexion = 0.0;    ///< [rad]
  Eigen::Vector3d F_ext_T = Eigen::Vector3d::Zero();  ///< on the tibia, tibia frame [N]
  Eigen::Vector3d M_ext_T = Eigen::Vector3d::Zero();  ///< about the tibia origin [N m]
  /// Load on the foot about the leg model's ankle centre, tibia frame
  /// (KneeLoads::F_foot_T, M_foot_T, ankle_centre_T); used only with
  /// ComakOptions::ankle_equilibrium, which needs has_foot_load.
  bool has_foot_load = false;
  Eigen::Vector3d F_foot_T = Eigen::Vector3d::Zero();  ///< [N]
  Eigen::Vector3d M_foot_T = Eigen::Vector3d::Zero();  ///< [N m]
  Eigen::Vector3d ankle_centre_T = Eigen::Vector3d::Zero();  ///< [m]
  /// Lab motion of the femur frame (the model's world; origin at the knee
  /// centre of the trial's leg chain, axes of its thigh frame) at t - step,
  /// t, t + step along the trial's local Taylor path, and the knee flexion's
  /// velocity and acceleration [rad/s, rad/s^2] in velocity/acceleration
  /// (its `coordinate` is set by the problem). Used only with
  /// ComakOptions::body_inertia, which needs has_femur_motion.
  bool has_femur_motion = false;
  RootMotion femur_motion;
  /// Model dynamics (a model with its own leg that reaches the ground,
  /// model_loads.h; frames from comak_model_frame_inputs): every model
  /// coordinate's value and rates from the trial by name (NaN where the
  /// trial has no column: only secondary coordinates may lack one), and the
  /// trial's forces on the model's bodies. F_ext_T, M_ext_T and the foot
  /// load are then unused.
  bool model_dynamics = false;
  Eigen::VectorXd q_trial, qd_trial, qdd_trial;
  std::vector<LabForce> lab_forces;
  /// The previous frame's coordinates and the time since it (set by
  /// run_comak; for the coordinate dampers). The first frame's previous pose
  /// is the passive settle it starts from, one frame spacing earlier.
  bool has_previous = false;
  Eigen::VectorXd q_previous;
  double dt_previous = 0.0;
  /// Why this frame has no finite input, naming the trial file, line and
  /// column (set by comak_frame_inputs for the first frame after a trial
  /// that ended early at a non-finite value; its values are then NaN).
  /// Empty otherwise. Solving such a frame throws NumericalError with it.
  std::string invalid_input;
};

/// Ipopt's multipliers at a solution (for a primal-dual warm start).
struct ComakMultipliers {
  Eigen::VectorXd lambda;            ///< equilibrium rows (scaled NLP units)
  Eigen::VectorXd z_lower, z_upper;  ///< bound multipliers per variable
};

enum class ComakFrameStatus { kConverged = 0, kFailed = 1 };

struct ComakFrameResult {
  ComakFrameStatus status = ComakFrameStatus::kFailed;
  int ipopt_status = 0;          ///< Ipopt::ApplicationReturnStatus of the last attempt
  std::string ipopt_status_name;
  int iterations = 0;            ///< Ipopt iterations of all attempts
  int attempts = 0;              ///< Ipopt solves: 1, 2 with the second start or one retry, up to 4
  double objective = 0.0;        ///< sum w V a^2 + reserve terms (unscaled) [m^3]
  double max_force_residual = 0.0;   ///< max |c| over prismatic rows [N]
  double max_moment_residual = 0.0;  ///< max |c| over revolute rows [N m]
  double wall_time = 0.0;        ///< [s], all attempts
  Eigen::VectorXd q;             ///< all model coordinates
  Eigen::VectorXd activations;   ///< one per muscle
  Eigen::VectorXd reserves;      ///< one per free coordinate (0 when off) [N or N m]
  std::string message;           ///< one line with the above
  ComakMultipliers multipliers;  ///< of the last attempt
};

/// The NLP of one frame (exposed for tests: residual and Jacobian checks).
class ComakProblem {
 public:
  ComakProblem(const Model& model, const ComakOptions& options);

  /// Free coordinates (12), the secondary ones (11) and the flexion index.
  const std::vector<int>& free_coordinates() const { return free_; }
  /// Coordinates whose equilibrium is a constraint row: the free ones, then
  /// the ankle with options().ankle_equilibrium (12 or 13 rows).
  const std::vector<int>& equilibrium_coordinates() const { return rows_; }
  int num_rows() const { return static_cast<int>(rows_.size()); }
  int ankle_coordinate() const { return ankle_; }
  /// External moment on the foot about the model's ankle axis [N m]
  /// (the ankle row's external term; 0 without ankle_equilibrium).
  double external_ankle_moment(const ComakFrameInput& in) const;
  const std::vector<int>& secondary_coordinates() const { return secondary_; }
  int flexion_coordinate() const { return flexion_; }
  int tibia_body() const { return tibia_; }
  /// Volume weights V_i [m^3] and weights w_i.
  const Eigen::VectorXd& volume_weights() const { return V_; }
  const Eigen::VectorXd& muscle_weights() const { return w_; }
  /// S_k per equilibrium row and whether it is revolute.
  const Eigen::VectorXd& row_scale() const { return row_scale_; }
  bool revolute(int k) const { return revolute_[k]; }

  /// The full coordinate vector with the frame's prescribed values and the
  /// secondary coordinates taken from q_secondary_source.
  Eigen::VectorXd coordinates(const ComakFrameInput& in, const Eigen::VectorXd& q_source) const;
  /// Q_ext (all coordinates) at the kinematics in data.
  Eigen::VectorXd external_generalized_force(const ModelData& data, const ComakFrameInput& in) const;
  /// Weight and d'Alembert generalized forces of the tibia and patella at q
  /// (all coordinates; zero without options().body_inertia).
  Eigen::VectorXd inertial_generalized_force(const Eigen::VectorXd& q,
                                             const ComakFrameInput& in) const;
  /// Bodies whose inertial forces are added (tibia, and patella if present;
  /// with model dynamics every body the free coordinates move).
  const std::vector<int>& inertial_bodies() const { return inertial_bodies_; }
  /// The model has its own leg to the ground (model_loads.h): frames must
  /// come from comak_model_frame_inputs.
  bool model_dynamics() const { return model_dynamics_; }
  /// Generalized force of the coordinate dampers on the equilibrium rows'
  /// coordinates at q (zero without options().coordinate_damping or a
  /// previous frame); all coordinates.
  Eigen::VectorXd damping_generalized_force(const Eigen::VectorXd& q, const ComakFrameInput& in) const;
  /// The neutral start of a frame (secondary coordinates): the trial's
  /// secondary values when it has them (model dynamics), else the model's
  /// defaults with the patella flexed 0.7 x the knee.
  Eigen::VectorXd neutral_pose(const ComakFrameInput& in) const;
  /// Unscaled residual Q + Q_ext (+ Q_inertia) + e over the equilibrium rows [N, N m]
  /// (e: one per free coordinate, or empty; the ankle row has none).
  Eigen::VectorXd residual(ModelData& data, const ComakFrameInput& in, const Eigen::VectorXd& q,
                           const Eigen::VectorXd& a, const Eigen::VectorXd& e) const;
  /// d residual / d [a (muscles), s (secondary)]: rows x (m + 11).
  Eigen::MatrixXd residual_jacobian(ModelData& data, const ComakFrameInput& in,
                                    const Eigen::VectorXd& q, const Eigen::VectorXd& a) const;
  /// sum w V a^2 + reserve terms [m^3].
  double objective(const Eigen::VectorXd& a, const Eigen::VectorXd& e) const;

  const Model& model() const { return model_; }
  const ComakOptions& options() const { return options_; }

 private:
  const Model& model_;
  ComakOptions options_;
  std::vector<int> free_, secondary_, rows_, inertial_bodies_;
  Vec3 ankle_axis_T_ = Vec3::UnitZ(), ankle_origin_T_ = Vec3::Zero();
  std::vector<bool> revolute_;
  int flexion_ = -1, tibia_ = -1;
  int hip_[3] = {-1, -1, -1};
  int ankle_ = -1;
  bool model_dynamics_ = false;
  int ground_ = -1;
  /// Hip rows (hip_equilibrium): the hip coordinates, their joints, and the
  /// leg's bodies (every body the hip coordinates do not move).
  std::vector<int> hip_rows_, hip_joints_, leg_bodies_;
  void add_hip_moments(const KinematicsData& k, const std::vector<BodyWrench>& w, Eigen::VectorXd& Q) const;
  Eigen::VectorXd V_, w_, row_scale_;
};

/// Solves one frame from the start point (q_start: all coordinates, its
/// secondary entries are used; a_start: activations). settle_q: a passive
/// settle pose used by retry 1 (may be empty: then the retry settles from
/// q_start). Throws common::NumericalError naming the frame on NaN/Inf.
/// `warm`: multipliers of the previous frame for Ipopt's warm start of
/// attempt 1 (nullptr: primal start only).
ComakFrameResult solve_comak_frame(const ComakProblem& problem, ModelData& data,
                                   const ComakFrameInput& input, const Eigen::VectorXd& q_start,
                                   const Eigen::VectorXd& a_start,
                                   const ComakMultipliers* warm = nullptr);

/// Frame inputs of a knee-load series (frames first..last, every stride-th;
/// last = -1: the last frame of the trial). Throws InputError for an
/// empty/out-of-range selection. Non-finite values are passed on (the run
/// stops at that frame, naming it). For loads of a truncated trial
/// (KneeLoads::truncated) the selection is checked against the whole trial;
/// the frames before the cut are returned, followed by the first selected
/// frame after it with NaN values and invalid_input set, so run_comak solves
/// the frames it can and then stops naming the frame, file, line and column.
/// With `leg` (the leg model of the inverse dynamics, knee_loads.h) and
/// loads from the inverse dynamics, each frame also gets the femur's lab
/// motion and the flexion rate (has_femur_motion, for
/// ComakOptions::body_inertia); the leg chain's tibia pose must then match
/// the loads' X_WT (InputError otherwise: another leg model, or a left leg).
std::vector<ComakFrameInput> comak_frame_inputs(const KneeLoads& loads, int first, int last,
                                                int stride, const LegModel* leg = nullptr);

/// Frame inputs for a model with its own leg (ComakProblem::model_dynamics):
/// every coordinate of the model from the trial's kinematics columns by
/// name (GaitTrial::kinematics_*; every prescribed coordinate and the knee
/// flexion must have one, else InputError naming the kinematics file and the
/// missing names), and every ExternalForce of the trial acting on a body of
/// the model (those on other bodies are listed in `ignored`). Frames
/// first..last every stride-th (last = -1: the trial's last).
std::vector<ComakFrameInput> comak_model_frame_inputs(const Model& model, const GaitTrial& trial, int first,
                                                      int last, int stride,
                                                      std::vector<std::string>* ignored = nullptr);

struct ComakRunSummary {
  int frames = 0, converged = 0, failed = 0;
  std::vector<int> failed_frames;       ///< trial frame indices
  double wall_time = 0.0;               ///< [s], all frames
  int total_iterations = 0;
  SettleResult first_settle;            ///< the passive settle of the first frame
  /// Empty unless the run stopped early (ComakRunStopped): the reason,
  /// naming the frame. Frames counts the frames handed to on_frame before.
  std::string stopped;
};

/// Thrown by run_comak when a frame's input or evaluation is not finite:
/// the run stops at that frame. what() names the frame ("COMAK frame 12 (t =
/// 0.12 s): ...") and, for a truncated trial, the file, line and column;
/// `summary` covers the frames before it (each was handed to on_frame), so a
/// writer can still finish its file.
class ComakRunStopped : public common::NumericalError {
 public:
  ComakRunStopped(const std::string& what, int frame, ComakRunSummary summary)
      : common::NumericalError(what), frame(frame), summary(std::move(summary)) {}
  int frame;                ///< trial frame index of the frame that stopped the run
  ComakRunSummary summary;  ///< of the frames before it; summary.stopped = what()
};

/// What run_comak carries from one frame to the next: with it (and the
/// frames' inputs) the rest of a run is the same, bit for bit, as in an
/// uninterrupted run (checkpoint and resume, pipelines/comak_checkpoint.h).
/// Nothing else carries over: the model data's contact search caches change
/// only the speed of an evaluation, not its result (contact.h).
struct ComakRunState {
  int frames_done = 0;         ///< frames of the list solved and handed to on_frame
  Eigen::VectorXd q, a;        ///< start of the next frame (last converged frame, or the first settle)
  Eigen::VectorXd q_prev;      ///< the coordinate dampers' previous pose
  double t_prev = 0.0;         ///< its time [s]
  ComakMultipliers warm;       ///< of the last converged frame
  bool have_warm = false;
  /// Of the frames done (wall_time: their solves' wall time [s]).
  ComakRunSummary summary;
};

/// Runs frame after frame: the first from the passive settle at its flexion
/// (muscle tone options.settle.muscle_tone), each next one warm-started from
/// the previous converged frame. `on_frame` is called after every frame
/// (with the model data evaluated at the frame's solution) so a writer can
/// append it at once. A non-finite input or evaluation throws
/// ComakRunStopped; a frame that does not converge is marked failed and the
/// run goes on.
ComakRunSummary run_comak(
    const ComakProblem& problem, const std::vector<ComakFrameInput>& frames,
    const std::function<void(const ComakFrameInput&, const ComakFrameResult&, const ModelData&)>&
        on_frame);

/// The same, continuing from `resume` when given (the state after its
/// frames_done frames of the same list; the settle is not repeated), and
/// calling `on_state` after on_frame of every frame with the state the next
/// frame starts from (for checkpoints).
ComakRunSummary run_comak(
    const ComakProblem& problem, const std::vector<ComakFrameInput>& frames,
    const std::function<void(const ComakFrameInput&, const ComakFrameResult&, const ModelData&)>&
        on_frame,
    const ComakRunState* resume, const std::function<void(const ComakRunState&)>& on_state);

const char* to_string(ComakFrameStatus status);

}  // namespace arthrosim::musculoskeletal
