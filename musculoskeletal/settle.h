#pragma once
// Passive settle: static equilibrium of the free coordinates with some
// coordinates held fixed (e.g. the knee flexion angle and the prescribed hip
// and ankle angles):
//   find q_s such that Q_s(q_f, q_s) = 0,
// where Q are the generalized forces of ligaments, contact and a constant muscle
// tone (activation a_tone on every muscle, as COMAK's settle step uses
// 0.02 F_max). Gravity and inertia are not included (a static, unloaded joint).
//
// Default method (SettleMethod::kPseudoTransient): pseudo-transient
// continuation (Kelley & Keyes 1998, "Convergence analysis of pseudo-transient
// continuation"), described below after the scaling; the Levenberg-Marquardt
// method of the first version is kept as SettleMethod::kLevenbergMarquardt.
//
// Scaling (both methods): the scaled residual
//   r = S_r Q_s,  S_r = 1 for prismatic (N), 1/L for revolute (N m / L) rows,
// with variables scaled x = S_x q_s (rad, m / L), L = length_scale.
//
// Pseudo-transient continuation: instead of minimising |r|^2, follow the
// over-damped pseudo-dynamics D dx/dt = r (the joint slides downhill in
// potential energy towards a stable equilibrium) with linearised backward Euler
// steps
//   (D / tau - J) dx = r,    D = diag(|J_kk|)  (a stiffness-like "damping"),
// where the dimensionless pseudo time step tau grows by switched evolution
// relaxation, tau_k+1 = tau_k |r_k-1| / |r_k| (clamped to [tau/4, 10 tau]), so
// the iteration turns into Newton's method (tau -> inf) near the solution. A
// step that grows |r| by more than max_residual_growth is retried with
// tau / 4 (the pseudo time step is too long for the nonlinearity). Steps are
// limited as for LM.
// Why: on the bundled knee at full extension, LM on |r|^2 stalled with 6-9 N
// on knee_tz while Q was smooth along the stalled direction (see
// docs/model_format.md, "Passive settle"); the damped pseudo-dynamics does not
// need |r| to decrease monotonically.
//
// Levenberg-Marquardt: each iteration solves
//   (J^T J + lambda diag(J^T J)) dx = -J^T r
// with J = dr/dx from the model's central-difference dQ/dq, limits the step (max_step_rad,
// max_step_m), accepts it if |r| decreases (else lambda x 10), and stops when
// max |Q_s| is below the force and moment tolerances.
#include <Eigen/Core>
#include <string>
#include <vector>

#include "musculoskeletal/model.h"

namespace arthrosim::musculoskeletal {

enum class SettleMethod { kPseudoTransient, kLevenbergMarquardt };

struct SettleOptions {
  SettleMethod method = SettleMethod::kPseudoTransient;
  /// Initial pseudo time step tau [-] of the pseudo-transient method (> 0):
  /// tau = 1 moves each coordinate about half-way to where its own stiffness
  /// alone would put it.
  double initial_pseudo_time = 1.0;
  /// A pseudo-transient step is accepted if |r| grows by at most this factor
  /// [-], >= 1 (else tau / 4 and retry). Measured on the coarse knee, cold
  /// starts at 0, 5, .., 90 deg: growth 2 -> 18 of 19 converge, 10 -> 19 of
  /// 19 (a test close to 1 makes the iteration creep where |r| has to rise on
  /// the way to the equilibrium; the step limits bound every move anyway).
  double max_residual_growth = 10.0;
  /// Coordinates held at their initial values (indices into q) in addition to
  /// the model's prescribed ones; everything else is solved for.
  std::vector<int> fixed;
  /// Activation applied to every muscle [-], 0..1 (COMAK settles with 0.02).
  double muscle_tone = 0.02;
  /// Convergence: max |Q| of prismatic free coordinates [N] ...
  double force_tolerance = 0.1;
  /// ... and of revolute free coordinates [N m].
  double moment_tolerance = 0.005;
  /// Iteration limit.
  int max_iterations = 100;
  /// Largest change per iteration [rad] and [m].
  double max_step_rad = 0.05, max_step_m = 0.002;
  /// Length that converts moments to forces in the scaling [m] (~joint size).
  double length_scale = 0.03;
  /// Initial Levenberg-Marquardt damping [-].
  double initial_damping = 1e-3;
  /// Options of the force evaluation (terms, FD step).
  ForceOptions forces;
};

enum class SettleStatus { kConverged, kMaxIterations, kStalled };

struct SettleResult {
  SettleStatus status = SettleStatus::kMaxIterations;
  int iterations = 0;
  Eigen::VectorXd q;               ///< final coordinates (all)
  double max_force_residual = 0;   ///< max |Q| over free prismatic coordinates [N]
  double max_moment_residual = 0;  ///< max |Q| over free revolute coordinates [N m]
  std::vector<double> history;     ///< |r| (scaled) per iteration
  std::string message;             ///< what happened, with the residuals
};

/// Solves for equilibrium starting at q0. Never throws on non-convergence:
/// the status and message say so (callers decide); throws on bad input.
SettleResult settle(const Model& model, ModelData& data, const Eigen::VectorXd& q0,
                    const SettleOptions& options);

}  // namespace arthrosim::musculoskeletal
