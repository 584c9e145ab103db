#pragma once
// Newton's method with a sparse direct solver, constraint elimination and an
// optional backtracking line search, for any nonlinear system G(x) = 0 whose
// tangent dG/dx has a known sparsity pattern. The HHT integrator
// (hht_integrator.h) solves each time step with it; a static or implicit
// stage can use it directly.
//
// Iteration (k = 0, 1, ...):
//   evaluate G(x_k) (constrained rows set to 0);
//   converged when both tests pass (norms over unconstrained coordinates):
//     residual:  ||G||_2 <= max(residual_rtol ||G(x_0)||_2, residual_atol)
//     increment: max_i w_i |dx_i| <= increment_rtol max_i w_i |x_i - x_ref,i| + increment_atol
//                (w: NewtonSystem::increment_weights; x_ref: solve()'s reference
//                point, e.g. the state at the start of a time step; at k = 0
//                the increment test is ||G|| <= residual_atol);
//   or by round-off stagnation: the last increment is below
//     roundoff_increment_rel x roundoff_scale (set_roundoff_scale) and the
//     residual has dropped by roundoff_residual_drop from its first value
//     (counted in statistics().roundoff_acceptances);
//   otherwise K dx = -G with K = dG/dx (constrained rows and columns replaced
//   by the identity, so dx = 0 there) and x_{k+1} = x_k + s dx, s = 1 or, with
//   line_search_halvings > 0, the first s in 1, 1/2, 1/4, ... with
//   ||G(x + s dx)|| <= (1 - 1e-4 s) ||G(x)|| (else the last s tried).
// A failure (max_iterations reached, a non-finite value, a failed
// factorisation, or a common::NumericalError thrown by the system) returns
// NewtonResult::converged = false with the reason; it never throws for them.
//
// Tangent economy: an iterate whose increment already passes the increment
// test is evaluated without the tangent first (it is converged as soon as its
// residual passes too); the tangent is assembled only if Newton goes on from
// it. With reuse_factorization (modified Newton) the last factorisation is
// kept across iterations and across solve() calls with the same tangent_key
// while the residual contracts by refactor_ratio per iteration.
//
// Linear solver: CHOLMOD when the system says its tangent is symmetric (or
// LinearSolverChoice::kCholmod forces it on the symmetric part (K + K^T)/2 of
// a non-symmetric tangent), else UMFPACK; a CHOLMOD factorisation that fails
// (not positive definite) switches to UMFPACK for good (counted, reported in
// statistics().linear_solver). The symbolic analysis is redone only when the
// system's pattern_revision() changes.
//
// Example (a static problem):
//   class MySystem : public numerics::NewtonSystem { ... };
//   MySystem sys;
//   numerics::NewtonSolver newton(sys, numerics::NewtonOptions{});
//   Eigen::VectorXd x = x_start;
//   const numerics::NewtonResult r = newton.solve(x, x_start);
//   if (!r.converged) throw common::NumericalError("my stage: " + r.reason);
#include <Eigen/Core>
#include <Eigen/SparseCore>
#include <memory>
#include <string>
#include <vector>

#include "numerics/sparse_direct_solver.h"

namespace arthrosim::numerics {

enum class LinearSolverChoice {
  kAuto,     ///< CHOLMOD when the tangent is symmetric, else UMFPACK
  kCholmod,  ///< force CHOLMOD; a non-symmetric tangent is replaced by its
             ///< symmetric part (K + K^T)/2 (more Newton iterations); switches
             ///< to UMFPACK, counted, on a matrix that is not SPD
  kUmfpack,  ///< force UMFPACK
};

/// What Newton needs from a nonlinear system G(x) = 0 of size() unknowns.
/// The system owns its data; the solver keeps a reference (the system must
/// outlive it).
class NewtonSystem {
 public:
  virtual ~NewtonSystem() = default;
  virtual int size() const = 0;
  /// G(x) (size n) and, when K != nullptr, the values of dG/dx in
  /// tangent_pattern()'s layout (K may arrive empty or with an older pattern:
  /// assign the whole matrix). Throws common::NumericalError naming where a
  /// non-finite value appeared, or when x is outside the admissible region.
  virtual void evaluate(const Eigen::VectorXd& x, Eigen::VectorXd& G, Eigen::SparseMatrix<double>* K) = 0;
  /// Compressed column pattern (values irrelevant), structurally symmetric.
  virtual const Eigen::SparseMatrix<double>& tangent_pattern() const = 0;
  /// Increases whenever tangent_pattern() changes (an evaluation may change
  /// it); the solver then redoes its symbolic analysis.
  virtual long pattern_revision() const { return 0; }
  /// True when every tangent is symmetric (CHOLMOD may be used).
  virtual bool tangent_symmetric() const = 0;
  /// 1 for coordinates fixed by a constraint (eliminated: their increment is
  /// 0 and their residual is ignored), else 0. Size n.
  virtual const std::vector<char>& constrained() const = 0;
  /// Per-coordinate weights of the increment test (see the file comment).
  virtual const Eigen::VectorXd& increment_weights() const = 0;
  /// Human-readable name of coordinate i, e.g. "node 12 r_z".
  virtual std::string describe_dof(int i) const = 0;
};

struct NewtonOptions {
  int max_iterations = 15;              ///< linear solves per solve() call, >= 1
  double residual_rtol = 1e-8;          ///< relative residual tolerance
  double residual_atol = 1e-10;         ///< absolute residual tolerance (unit of G)
  double increment_rtol = 1e-8;         ///< relative increment tolerance
  double increment_atol = 1e-14;        ///< absolute increment tolerance (unit of w x)
  double roundoff_increment_rel = 1e-11;  ///< see "round-off stagnation"
  double roundoff_residual_drop = 1e-3;   ///< required ||G|| / ||G(x_0)||
  /// Modified Newton: keep the factorisation while the residual contracts by
  /// refactor_ratio per iteration (not combined with the line search).
  bool reuse_factorization = false;
  double refactor_ratio = 0.25;
  /// Backtracking halvings of the Newton step (0 = full steps).
  int line_search_halvings = 0;
  /// Linear analysis: the iterate after the first Newton step is accepted
  /// whatever its residual (one solve with the tangent at the start point).
  bool linear = false;
  LinearSolverChoice solver = LinearSolverChoice::kAuto;
  /// Units named in failure messages.
  std::string residual_unit = "N";
  std::string increment_unit = "m";
};

struct NewtonResult {
  bool converged = false;
  std::string reason;                   ///< why it failed ("" when converged)
  double last_residual = 0;             ///< ||G|| of the last evaluated iterate
  std::vector<double> residual_norms;   ///< ||G|| at each iterate
  std::vector<double> increment_norms;  ///< weighted increment of each Newton step
};

/// Totals over every solve() of one solver.
struct NewtonStatistics {
  long iterations = 0;              ///< linear solves
  long factorizations = 0;
  long symbolic_analyses = 0;
  long solver_switches = 0;         ///< CHOLMOD -> UMFPACK after a non-SPD matrix
  long pattern_changes = 0;         ///< new symbolic analysis after a pattern change
  long line_search_reductions = 0;  ///< Newton steps shortened by the line search
  long roundoff_acceptances = 0;    ///< solves accepted by round-off stagnation
  double assembly_s = 0, factorization_s = 0, solve_s = 0;  ///< wall time
  std::string linear_solver;        ///< solver in use
};

/// The factorisation modified Newton keeps between solves
/// (NewtonOptions::reuse_factorization): the matrix that was factorised (with
/// the constrained rows and columns replaced by the identity, and symmetrised
/// when CHOLMOD took a non-symmetric tangent) and the tangent_key it was built
/// for. Checkpoints store it so that a resumed run refactorises exactly the
/// matrix the interrupted run was still using (docs/testing.md).
struct KeptFactorization {
  bool valid = false;
  double key = 0;
  Eigen::SparseMatrix<double> matrix;
};

class NewtonSolver {
 public:
  /// The system must outlive the solver. Throws common::InputError for
  /// options out of range.
  NewtonSolver(NewtonSystem& system, const NewtonOptions& options);
  ~NewtonSolver();

  /// Iterates from x (overwritten by the last iterate) until converged or
  /// failed (see the file comment). x_ref: reference point of the relative
  /// increment test. tangent_key: a reused factorisation is valid only for
  /// solves with the same key (e.g. the time step size).
  NewtonResult solve(Eigen::VectorXd& x, const Eigen::VectorXd& x_ref, double tangent_key = 0);
  /// Scale of x for the round-off stagnation test (e.g. the largest weighted
  /// coordinate); 1 by default.
  void set_roundoff_scale(double scale) { x_scale_ = scale; }
  /// Load-relative convergence (off while load_tol <= 0): an iterate also
  /// converges when ||G|| <= load_tol * load_norm (load_norm: norm of the
  /// applied load, unit of G) and its weighted increment is at most
  /// load_tol * max_i w_i |x_i - x_solution_ref_i| (relative to the solution
  /// measured from x_solution_ref, e.g. the reference configuration). Set
  /// before each solve; it stays until changed.
  void set_load_criterion(double load_tol, double load_norm, const Eigen::VectorXd& x_solution_ref) {
    load_tol_ = load_tol;
    load_norm_ = load_norm;
    x_solution_ref_ = x_solution_ref;
  }
  /// Forgets a kept factorisation (the next iteration refactorises).
  void invalidate_factorization() { factor_valid_ = false; }

  const NewtonStatistics& statistics() const { return stats_; }
  /// Checkpoint and resume (docs/testing.md): the counters and the linear
  /// solver in use (after a CHOLMOD -> UMFPACK switch) of an earlier solver,
  /// set on a fresh one. A kept factorisation (reuse_factorization) is
  /// carried over separately (kept_factorization / restore_kept_factorization).
  void restore_statistics(const NewtonStatistics& s);
  /// The factorisation kept for the next solve (valid only with
  /// reuse_factorization and after a successful factorisation).
  KeptFactorization kept_factorization() const;
  /// Factorises k.matrix again and keeps it for solves with tangent_key
  /// k.key, as the solver that wrote it had it; call after
  /// restore_statistics. The symbolic analysis this needs is counted (as the
  /// first factorisation of a resumed run counts it), the numeric
  /// factorisation is not (the interrupted run counted it). Throws
  /// common::InputError when the matrix does not have the system's tangent
  /// pattern, common::NumericalError when it cannot be factorised.
  void restore_kept_factorization(const KeptFactorization& k);
  const NewtonOptions& options() const { return opts_; }

 private:
  bool factorize(Eigen::SparseMatrix<double>& K, std::string& reason);
  void constrain_matrix(Eigen::SparseMatrix<double>& K) const;
  void sync_pattern();
  void build_transpose_index();

  NewtonSystem& sys_;
  NewtonOptions opts_;
  double x_scale_ = 1.0;
  double load_tol_ = 0, load_norm_ = 0;
  Eigen::VectorXd x_solution_ref_;
  bool factor_valid_ = false, refactor_next_ = false;
  double factor_key_ = 0;
  Eigen::SparseMatrix<double> K_;
  Eigen::SparseMatrix<double> factored_;  ///< the matrix of the kept factorisation (reuse_factorization only)
  std::vector<int> zero_index_, diag_index_, transpose_index_;
  long pattern_revision_ = 0;
  std::unique_ptr<SparseDirectSolver> solver_;
  NewtonStatistics stats_;
};

}  // namespace arthrosim::numerics
