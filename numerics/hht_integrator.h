#pragma once
// Hilber-Hughes-Taylor (HHT-alpha) time integration with Newton iterations
// (newton.h), and a quasi-static mode, for any TimeIntegrable (e.g. the
// cartilage stage's shell models); no assumption about the coordinates.
//
// HHT (Hilber, Hughes & Taylor 1977), alpha in [-1/3, 0],
// gamma = (1 - 2 alpha)/2, beta = (1 - alpha)^2/4:
//   M a_{n+1} + (1 + alpha) F(q_{n+1}, v_{n+1}, t_{n+1}) - alpha F(q_n, v_n, t_n) = 0
//   q_{n+1} = q_n + h v_n + h^2 ((1/2 - beta) a_n + beta a_{n+1})
//   v_{n+1} = v_n + h ((1 - gamma) a_n + gamma a_{n+1})
// Unknown: q_{n+1} (a, v follow from the Newmark relations); Newton matrix
//   ka M + (1 + alpha)(dF/dq + kv dF/dv),  ka = 1/(beta h^2), kv = gamma/(beta h).
// alpha = 0 is the trapezoidal rule (no numerical dissipation).
// Quasi-static mode: F(q_{n+1}, 0, t_{n+1}) = 0 at each time (load) step.
//
// Convergence of a step (both must hold; norms over unconstrained coordinates):
//   residual:  ||G||_2 <= max(residual_rtol * ||G^(0)||_2, residual_atol_N)
//              (G^(0): residual of the step's first iterate, in N);
//   increment: max_i w_i |dq_i| <= increment_rtol * max_i w_i |q_i - q_n,i| + increment_atol_m
//              (w = TimeIntegrable::increment_weights, e.g. 1 for positions,
//              h/2 for a shell's transverse gradients, so both are lengths in m).
// Round-off stagnation (documented exception): when the increment has dropped
// below roundoff_increment_rel * (largest position coordinate) -- a few
// thousand ulps -- and the residual has fallen by roundoff_residual_drop from
// its first value, the iterate cannot be improved in double precision and the
// step is accepted (counted in statistics.roundoff_acceptances). This matters
// for very thin shells, whose residual floor eps * E t L can exceed
// residual_atol_N.
// Quasi-static predictor: q_{n+1}^(0) = q_n + (h/h_prev)(q_n - q_{n-1})
// (extrapolate_predictor), which saves most of the Newton iterations of
// load-controlled large-rotation paths.
// A step whose Newton iteration does not converge in max_newton_iterations,
// or meets a non-finite value or a failed factorisation, is rejected (counted,
// reason logged) and retried with half the step; after max_halvings
// consecutive halvings, or when a step no longer than min_step_fraction dt_s
// fails (rare successes of ever shorter steps must not creep on without
// end), the run stops with common::NumericalError naming the time and the
// residual. After steps_before_growth successful steps the step doubles
// again, up to dt_s.
#include <Eigen/Core>
#include <Eigen/SparseCore>
#include <functional>
#include <memory>
#include <string>
#include <vector>

#include "common/options.h"
#include "numerics/newton.h"
#include "numerics/time_integrable.h"

namespace arthrosim::numerics {

struct IntegratorOptions {
  bool quasi_static = false;       ///< no inertia, F(q, 0, t) = 0 per step
  double alpha = -0.2;             ///< HHT alpha in [-1/3, 0]; seed 002: -0.2
  double dt_s = 1e-4;              ///< nominal step [s] (> 0); seed 002: 1e-4 s
  int max_newton_iterations = 15;  ///< per attempt, >= 1
  double residual_rtol = 1e-8;     ///< relative residual tolerance
  double residual_atol_N = 1e-10;  ///< absolute residual tolerance [N]
  double increment_rtol = 1e-8;    ///< relative increment tolerance
  double increment_atol_m = 1e-11 * common::units::mm;  ///< absolute increment tolerance [m]
  double roundoff_increment_rel = 1e-11;  ///< see "round-off stagnation"
  double roundoff_residual_drop = 1e-3;   ///< required ||G|| / ||G^(0)||
  bool extrapolate_predictor = true;      ///< quasi-static secant predictor
  /// Newton start of a step: kPrevious = q_n (quasi-static: with the secant
  /// extrapolation above); kSystem = TimeIntegrable::predict (e.g. the
  /// surfaces carried by their bones' imposed motion); kSystemExtrapolated
  /// = TimeIntegrable::predict_extrapolated with the step before (e.g. the
  /// bone-relative deformation extrapolated linearly in time as well), kSystem
  /// on the first step.
  enum class Predictor { kPrevious, kSystem, kSystemExtrapolated };
  Predictor predictor = Predictor::kPrevious;
  /// Modified Newton: keep the last factorisation across iterations and steps
  /// (same step size) while the residual contracts by refactor_ratio per
  /// iteration; otherwise re-assemble and refactorise. Off by default
  /// (full Newton, quadratic convergence).
  bool reuse_factorization = false;
  double refactor_ratio = 0.25;
  /// Backtracking line search on the residual norm (Newton globalisation,
  /// e.g. for penalty contact, whose active set changes between iterates): up
  /// to this many halvings of the Newton step; 0 = full steps (pure Newton).
  /// Not combined with reuse_factorization.
  int line_search_halvings = 0;
  /// > 0: a step also converges when ||G|| <= load_rtol ||F_load(t)|| and the
  /// weighted increment is <= load_rtol x the largest weighted distance of
  /// the iterate from the initial state (NewtonSolver::set_load_criterion);
  /// ||F_load(t)||: norm of F at the initial state with the constraints of t
  /// (the applied loads, and the forces of prescribed motion), unconstrained
  /// coordinates. 0: off.
  double load_rtol = 0;
  /// Linear analysis: each step is one Newton solve from its start, accepted
  /// as it is (a steady state from the reference configuration: the
  /// small-displacement solution).
  bool linear = false;
  int max_halvings = 10;           ///< consecutive halvings before giving up
  /// A failed step no longer than this fraction of dt_s stops the run, in (0, 1).
  double min_step_fraction = 1.0 / (1 << 20);
  int steps_before_growth = 4;     ///< successful steps before doubling dt back
  LinearSolverChoice solver = LinearSolverChoice::kAuto;
  bool keep_step_log = true;       ///< keep per-step residual histories
  /// Called at once for every rejected (halved) step with its record line
  /// (also kept in statistics().rejections), so a caller can report it while
  /// a single advance_to() is still creeping on with short steps.
  std::function<void(const std::string& rejection)> on_rejection;

  /// Scene keys of a stage that integrates with these options
  /// (common/options.h): time_step_s, hht_alpha, max_newton_iterations,
  /// newton_tolerance (residual_rtol; increment_rtol takes the same value,
  /// see same_tolerances()), newton_residual_floor_n, newton_increment_floor_mm,
  /// linear_solver, newton_reuse_factorization.
  void declare(common::OptionVisitor& v);
  /// increment_rtol = residual_rtol (one scene key sets both).
  void same_tolerances() { increment_rtol = residual_rtol; }
};

enum class IntegratorStatus { kNotStarted, kRunning, kFailed };

struct StepRecord {
  double t_start = 0, dt = 0;
  std::vector<double> residual_norms;   ///< ||G|| at each iterate [N]
  std::vector<double> increment_norms;  ///< weighted increment [m]
};

struct IntegratorStatistics {
  IntegratorStatus status = IntegratorStatus::kNotStarted;
  long steps = 0;              ///< accepted steps
  long rejected_steps = 0;     ///< attempts rejected (each one halves the step)
  long newton_iterations = 0;  ///< linear solves in accepted + rejected attempts
  long factorizations = 0;
  long symbolic_analyses = 0;
  long solver_switches = 0;    ///< CHOLMOD -> UMFPACK after a non-SPD matrix
  long pattern_changes = 0;    ///< tangent pattern changed (contact): new symbolic analysis
  long line_search_reductions = 0;  ///< Newton steps shortened by the line search
  long roundoff_acceptances = 0;  ///< steps accepted by round-off stagnation
  double assembly_s = 0, factorization_s = 0, solve_s = 0, total_s = 0;  ///< wall time
  std::string linear_solver;   ///< solver in use
  std::vector<std::string> rejections;  ///< "t=..., dt=...: reason"
  std::vector<StepRecord> log;          ///< accepted steps (if keep_step_log)
};

/// Everything an HhtIntegrator carries from one step to the next (checkpoint
/// and resume, docs/testing.md): with it restored after initialize(), the
/// following steps are the same, bit for bit, as without the interruption.
struct HhtState {
  double t = 0, dt = 0, h_prev = 0;
  int successes_since_halving = 0;
  Eigen::VectorXd q, v, a, F, q_initial, dq_prev;
  long steps = 0, rejected_steps = 0;
  std::vector<std::string> rejections;
  /// The Newton solver's counters and linear solver in use (timings too).
  NewtonStatistics newton;
  /// The factorisation modified Newton keeps (newton_reuse_factorization;
  /// invalid otherwise): restored, the next step reuses the same factors.
  KeptFactorization kept;
  double initial_assembly_s = 0, total_s = 0;
};

class HhtIntegrator {
 public:
  /// The system must outlive the integrator.
  HhtIntegrator(TimeIntegrable& system, const IntegratorOptions& options);
  ~HhtIntegrator();

  /// Sets the initial state (constraints applied at t0) and, in dynamic mode,
  /// the initial acceleration from M a0 = -F(q0, v0, t0).
  void initialize(double t0, const Eigen::VectorXd& q0, const Eigen::VectorXd& v0 = Eigen::VectorXd());
  /// Advances to t_end in steps of at most dt_s (halving when needed).
  void advance_to(double t_end);
  /// Dynamic path to a steady state (e.g. the osmotic swelling from rest):
  /// advances by dt_s at a time (advance_to, so with the same halving and
  /// failure rules) until the largest weighted change of the coordinates over
  /// one such step, max_i w_i |q_i(t + dt_s) - q_i(t)| with the increment
  /// weights (m; it bounds every node's deflection change), is at most
  /// change_tol_m, or until t_max. Returns true when the steady state was
  /// reached, false when t_max came first; last_change_m (if given) receives
  /// the last step's change. With a geometric decay of the transient by a
  /// factor rho per step, the remaining distance to the steady state is about
  /// change x rho / (1 - rho) (docs/shell_element.md, section 4).
  bool advance_to_steady_state(double change_tol_m, double t_max, double* last_change_m = nullptr);

  double time() const { return t_; }
  const Eigen::VectorXd& q() const { return q_; }
  const Eigen::VectorXd& v() const { return v_; }
  const Eigen::VectorXd& a() const { return a_; }
  double current_dt() const { return dt_; }
  const IntegratorStatistics& statistics() const { return stats_; }
  const IntegratorOptions& options() const { return opts_; }

  /// The state after the last accepted step (checkpoints).
  HhtState state() const;
  /// Continues from `s` (after initialize() on the same system and options;
  /// the step log restarts empty). Sizes are checked (InputError).
  void restore(const HhtState& s);

 private:
  class StepSystem;
  /// One attempt from (t_, q_, v_, a_) over h; true on convergence (state
  /// advanced). On failure the state is untouched and `reason` says why.
  bool attempt(double h, std::string& reason, double& last_residual);
  /// Newton's counters and timings into stats_.
  void copy_newton_statistics();

  TimeIntegrable& sys_;
  IntegratorOptions opts_;
  double gamma_ = 0.5, beta_ = 0.25;
  double t_ = 0, dt_ = 0;
  int successes_since_halving_ = 0;
  Eigen::VectorXd q_, v_, a_, F_;  // F_: F at the current accepted state
  Eigen::VectorXd q_initial_;        // initialize()'s state (load_rtol)
  Eigen::VectorXd dq_prev_;          // last accepted step's change (predictor)
  double h_prev_ = 0;
  double initial_assembly_s_ = 0;    // initialize()'s evaluation
  std::unique_ptr<StepSystem> step_;    // the step equation as a Newton system
  std::unique_ptr<NewtonSolver> newton_;
  IntegratorStatistics stats_;
};

}  // namespace arthrosim::numerics
