#pragma once
// Time integration of the biphasic first-order system (seed 000, eqs 14-16)
// by the generalised trapezoidal rule.
//
//   u_{i+1} = u_i + dt (omega v_{i+1} + (1 - omega) v_i)                 (15)
//   [omega dt K  -A] [v_{i+1}]   [F_t - K (u_i + (1 - omega) dt v_i)]
//   [-A^T        -B] [p_{i+1}] = [F_Q                               ]   (16)
//
// with the loads and prescribed values of t_{i+1}. Dirichlet conditions
// (prescribed displacement on a fixed set of u-dofs, prescribed pressure on a
// fixed set of p-dofs) are eliminated; (15) turns a prescribed displacement
// into the velocity it implies. The sets are fixed for the whole run, so the
// coefficient matrix (free-free block) is the same at every step for a
// constant dt: it is factored ONCE (UMFPACK LU through
// numerics::SparseDirectSolver; the matrix is symmetric indefinite) in the
// constructor, and each step costs one forward and one back substitution plus
// two sparse products. counters() records this.
//
// omega in [1/2, 1]: 1 is backward Euler (first order, L-stable: a step load
// gives no oscillation in time), 1/2 is the trapezoidal rule (second order,
// A-stable but not L-stable: after a step load the stiff modes flip sign every
// step without decaying). docs/biphasic.md gives the measured rates and the
// reason for the default.
//
// The free-free matrix is scaled symmetrically before factorisation (u rows by
// 1/sqrt(omega dt K_ii), p rows by 1/sqrt of a Schur-complement diagonal
// estimate) because its blocks differ by ~15 orders of magnitude in SI units
// (H ~ 1e6 Pa, k ~ 1e-15 m^4/(N s)); the scaled relative residual of every
// solve is recorded.
#include <Eigen/Core>
#include <Eigen/SparseCore>
#include <memory>
#include <string>
#include <vector>

#include "biphasic/layer_system.h"

namespace arthrosim::numerics {
class SparseDirectSolver;
}

namespace arthrosim::biphasic {

struct TrapezoidalOptions {
  /// Time step dt [s]; > 0; constant for the run.
  double time_step_s = 0.0;
  /// Generalised trapezoidal parameter omega [-]; in [0.5, 1]. Default 1
  /// (backward Euler), see the header comment and docs/biphasic.md.
  double omega = 1.0;
};

/// Cost and health of a run (counts are what the "factor once" requirement
/// is checked against).
struct IntegratorCounters {
  int factorizations = 0;        ///< numeric LU factorisations (1 per run)
  int solves = 0;                ///< forward/back substitution pairs (1 per step)
  int free_dofs = 0;             ///< size of the factored system
  int fixed_dofs = 0;            ///< eliminated Dirichlet dofs
  long long matrix_nonzeros = 0; ///< nonzeros of the factored matrix
  double factorization_s = 0.0;  ///< wall time of the factorisation (incl. analysis) [s]
  double solve_s = 0.0;          ///< wall time of all substitutions [s]
  double step_s = 0.0;           ///< wall time of all steps (rhs, solve, update) [s]
  double max_relative_residual = 0.0;  ///< max over steps of |M y - b| / |b| (scaled system)
};

/// Values at t_{i+1} for one step. Empty vectors mean zero.
struct StepInput {
  Eigen::VectorXd u_fixed;  ///< prescribed displacement of each fixed u-dof [m] (order of fixed_u)
  Eigen::VectorXd p_fixed;  ///< prescribed pressure of each fixed p-dof [Pa] (order of fixed_p)
  Eigen::VectorXd F_t;      ///< external load vector (nu) [N]
  Eigen::VectorXd F_Q;      ///< prescribed-flux vector (np) [m^3/s]
};

/// What carries over from one step to the next (a checkpoint of the run,
/// pipelines/biphasic_checkpoint.h): restoring it into an integrator built
/// from the same system and options continues bit-identically (the
/// factorisation is rebuilt by the constructor; factorising the same matrix
/// gives the same factors). Wall times are restored too, as accumulated so far.
struct TrapezoidalState {
  double time = 0.0;
  int steps = 0;
  Eigen::VectorXd u, v, p, last_F_t, last_F_Q;
  int solves = 0;
  double solve_s = 0.0, step_s = 0.0, max_relative_residual = 0.0;
};

class TrapezoidalIntegrator {
 public:
  /// `fixed_u`: u-dof indices with prescribed displacement; `fixed_p`: p-dof
  /// indices with prescribed pressure (both without duplicates). The state
  /// starts at rest (u = v = p = 0, t = 0). Factorises the matrix; throws
  /// common::NumericalError naming the layer if it is singular, and
  /// common::InputError for invalid options or indices.
  TrapezoidalIntegrator(const LayerSystem& system, std::vector<int> fixed_u,
                        std::vector<int> fixed_p, TrapezoidalOptions options);
  ~TrapezoidalIntegrator();
  TrapezoidalIntegrator(const TrapezoidalIntegrator&) = delete;
  TrapezoidalIntegrator& operator=(const TrapezoidalIntegrator&) = delete;

  /// Advances from t_i to t_{i+1} = t_i + dt with the values of t_{i+1}.
  /// Throws common::NumericalError naming the layer and step on NaN/Inf.
  void step(const StepInput& input);

  double time() const { return time_; }
  int steps() const { return steps_; }
  const Eigen::VectorXd& u() const { return u_; }  ///< displacement (nu) [m]
  const Eigen::VectorXd& v() const { return v_; }  ///< solid velocity (nu) [m/s]
  const Eigen::VectorXd& p() const { return p_; }  ///< pressure (np) [Pa]
  /// K u - A p - F_t at t_i (nu) [N]: zero (to solve accuracy) on free dofs,
  /// the support reaction on fixed ones.
  Eigen::VectorXd reaction() const;
  /// -A^T v - B p - F_Q at t_i (np) [m^3/s]: zero on free p-dofs; on fixed
  /// ones the nodal fluid volume flow INTO the domain's boundary node's
  /// control volume, i.e. minus the outflow through it.
  Eigen::VectorXd flux_reaction() const;
  const IntegratorCounters& counters() const { return counters_; }
  TrapezoidalState state() const;
  /// Continues from `s` (sizes checked: std::invalid_argument naming the layer).
  void restore(const TrapezoidalState& s);
  const std::vector<int>& fixed_u() const { return fixed_u_; }
  const std::vector<int>& fixed_p() const { return fixed_p_; }
  const TrapezoidalOptions& options() const { return options_; }

 private:
  const LayerSystem& system_;
  std::vector<int> fixed_u_, fixed_p_;
  TrapezoidalOptions options_;
  std::vector<int> free_;           // full index (v then p) of each free unknown
  std::vector<int> fixed_;          // full index of each fixed unknown (u first, then p)
  Eigen::SparseMatrix<double> M_ff_scaled_, M_fc_;
  Eigen::VectorXd scale_;           // D (free)
  std::unique_ptr<numerics::SparseDirectSolver> solver_;
  Eigen::VectorXd u_, v_, p_, last_F_t_, last_F_Q_;
  double time_ = 0.0;
  int steps_ = 0;
  IntegratorCounters counters_;
};

}  // namespace arthrosim::biphasic
