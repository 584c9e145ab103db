#include "numerics/newton.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>
#include <sstream>

#include "common/error.h"

namespace arthrosim::numerics {
namespace {

using Clock = std::chrono::steady_clock;
double since(Clock::time_point t0) { return std::chrono::duration<double>(Clock::now() - t0).count(); }

double weighted_max(const Eigen::VectorXd& x, const Eigen::VectorXd& w) {
  return (x.cwiseAbs().cwiseProduct(w)).maxCoeff();
}

}  // namespace

NewtonSolver::NewtonSolver(NewtonSystem& system, const NewtonOptions& options) : sys_(system), opts_(options) {
  if (opts_.max_iterations < 1)
    throw common::InputError("Newton: max_iterations must be >= 1, found " + std::to_string(opts_.max_iterations));
  if (opts_.line_search_halvings < 0)
    throw common::InputError("Newton: line_search_halvings must be >= 0, found " +
                             std::to_string(opts_.line_search_halvings));
  sync_pattern();
  LinearSolverKind kind = LinearSolverKind::kUmfpack;
  if (opts_.solver == LinearSolverChoice::kCholmod ||
      (opts_.solver == LinearSolverChoice::kAuto && sys_.tangent_symmetric()))
    kind = LinearSolverKind::kCholmod;
  solver_ = std::make_unique<SparseDirectSolver>(kind);
  stats_.linear_solver = to_string(kind);
}

NewtonSolver::~NewtonSolver() = default;

void NewtonSolver::restore_statistics(const NewtonStatistics& s) {
  // The system's pattern as it is now (restored with the system), without
  // counting a change: the counters are the earlier solver's.
  sync_pattern();
  const LinearSolverKind kind =
      s.linear_solver == to_string(LinearSolverKind::kUmfpack) ? LinearSolverKind::kUmfpack : LinearSolverKind::kCholmod;
  if (kind != solver_->kind()) solver_ = std::make_unique<SparseDirectSolver>(kind);
  factor_valid_ = false;
  stats_ = s;
  stats_.linear_solver = to_string(kind);
}

KeptFactorization NewtonSolver::kept_factorization() const {
  KeptFactorization k;
  k.valid = opts_.reuse_factorization && factor_valid_;
  if (k.valid) {
    k.key = factor_key_;
    k.matrix = factored_;
  }
  return k;
}

void NewtonSolver::restore_kept_factorization(const KeptFactorization& k) {
  factor_valid_ = false;
  if (!k.valid) return;
  if (!opts_.reuse_factorization)
    throw common::InputError("Newton: a kept factorisation restored into a solver without reuse_factorization");
  const auto& P = sys_.tangent_pattern();
  const auto& M = k.matrix;
  const bool same = M.rows() == P.rows() && M.cols() == P.cols() && M.nonZeros() == P.nonZeros() &&
                    M.isCompressed() &&
                    std::equal(P.outerIndexPtr(), P.outerIndexPtr() + P.outerSize() + 1, M.outerIndexPtr()) &&
                    std::equal(P.innerIndexPtr(), P.innerIndexPtr() + P.nonZeros(), M.innerIndexPtr());
  if (!same)
    throw common::InputError("Newton: the kept factorisation's matrix (" + std::to_string(M.rows()) + " x " +
                             std::to_string(M.cols()) + ", " + std::to_string(M.nonZeros()) +
                             " entries) does not have the system's tangent pattern (" + std::to_string(P.rows()) +
                             " x " + std::to_string(P.cols()) + ", " + std::to_string(P.nonZeros()) + " entries)");
  factored_ = M;
  if (!solver_->analyzed()) {
    solver_->analyze(factored_);
    ++stats_.symbolic_analyses;
  }
  if (!solver_->factorize(factored_))
    throw common::NumericalError("Newton: the kept factorisation could not be refactorised: " + solver_->message());
  factor_valid_ = true;
  factor_key_ = k.key;
  refactor_next_ = false;
}

void NewtonSolver::sync_pattern() {
  // Constraint elimination indices in the pattern (rows/cols -> identity).
  const auto& P = sys_.tangent_pattern();
  const auto& c = sys_.constrained();
  zero_index_.clear();
  diag_index_.clear();
  for (int j = 0; j < P.outerSize(); ++j)
    for (int k = P.outerIndexPtr()[j]; k < P.outerIndexPtr()[j + 1]; ++k) {
      const int i = P.innerIndexPtr()[k];
      if (c[i] || c[j]) (i == j ? diag_index_ : zero_index_).push_back(k);
    }
  // The transpose map (CHOLMOD on the symmetric part) is rebuilt only when
  // it is needed: with UMFPACK it never is, and contact changes the pattern
  // often.
  transpose_index_.clear();
  if (solver_ && pattern_revision_ != sys_.pattern_revision()) {
    // A new pattern needs a new symbolic analysis (counted when it is done).
    solver_ = std::make_unique<SparseDirectSolver>(solver_->kind());
    factor_valid_ = false;
    ++stats_.pattern_changes;
  }
  pattern_revision_ = sys_.pattern_revision();
}

void NewtonSolver::build_transpose_index() {
  // Transpose map of the (structurally symmetric) pattern, for the symmetric
  // part (K + K^T)/2 handed to CHOLMOD when the tangent is not symmetric.
  const auto& P = sys_.tangent_pattern();
  transpose_index_.resize(P.nonZeros());
  for (int j = 0; j < P.outerSize(); ++j)
    for (int k = P.outerIndexPtr()[j]; k < P.outerIndexPtr()[j + 1]; ++k) {
      const int i = P.innerIndexPtr()[k];
      const int* begin = P.innerIndexPtr() + P.outerIndexPtr()[i];
      const int* end = P.innerIndexPtr() + P.outerIndexPtr()[i + 1];
      const int* it = std::lower_bound(begin, end, j);
      if (it == end || *it != j) throw common::InputError("Newton: tangent pattern is not structurally symmetric");
      transpose_index_[k] = static_cast<int>(it - P.innerIndexPtr());
    }
}

void NewtonSolver::constrain_matrix(Eigen::SparseMatrix<double>& K) const {
  double* v = K.valuePtr();
  for (int k : zero_index_) v[k] = 0;
  for (int k : diag_index_) v[k] = 1;
}

bool NewtonSolver::factorize(Eigen::SparseMatrix<double>& K, std::string& reason) {
  auto t0 = Clock::now();
  if (solver_->kind() == LinearSolverKind::kCholmod && !sys_.tangent_symmetric()) {
    // Symmetric approximation of a non-symmetric tangent: (K + K^T)/2.
    // Newton then converges linearly at a rate set by the skew part.
    if (transpose_index_.size() != static_cast<size_t>(K.nonZeros())) build_transpose_index();
    double* v = K.valuePtr();
    for (size_t k = 0; k < transpose_index_.size(); ++k) {
      const size_t t = static_cast<size_t>(transpose_index_[k]);
      if (t > k) {
        const double m = 0.5 * (v[k] + v[t]);
        v[k] = v[t] = m;
      }
    }
  }
  if (!solver_->analyzed()) {
    solver_->analyze(K);
    ++stats_.symbolic_analyses;
  }
  if (opts_.reuse_factorization) factored_ = K;  // what a checkpoint of the kept factorisation holds
  bool ok = solver_->factorize(K);
  ++stats_.factorizations;
  if (!ok && solver_->kind() == LinearSolverKind::kCholmod) {
    // Reported switch, not a silent fallback: counted in statistics.
    ++stats_.solver_switches;
    solver_ = std::make_unique<SparseDirectSolver>(LinearSolverKind::kUmfpack);
    stats_.linear_solver = to_string(LinearSolverKind::kUmfpack);
    solver_->analyze(K);
    ++stats_.symbolic_analyses;
    ok = solver_->factorize(K);
    ++stats_.factorizations;
  }
  stats_.factorization_s += since(t0);
  if (!ok) reason = solver_->message();
  return ok;
}

NewtonResult NewtonSolver::solve(Eigen::VectorXd& x, const Eigen::VectorXd& x_ref, double tangent_key) {
  const int n = sys_.size();
  const auto& c = sys_.constrained();
  const Eigen::VectorXd& w = sys_.increment_weights();
  NewtonResult res;
  Eigen::VectorXd G, G_tangent, dx;
  // Constrained rows of a residual set to 0; returns its norm.
  auto constrained_norm = [&](Eigen::VectorXd& GG) {
    for (int i = 0; i < n; ++i)
      if (c[i]) GG(i) = 0;
    return GG.norm();
  };
  double r_ref = 0, last_inc = std::numeric_limits<double>::infinity();
  bool evaluated = false;  // G (and K_ if have_K) already hold the iterate (line search)
  bool have_K = false;
  // The increment test of an iterate is known before it is evaluated. An
  // iterate whose increment passes it is the converged one as soon as its
  // residual passes too, so it is evaluated without the tangent first (the
  // tangent is assembled after all only if Newton goes on from it).
  auto increment_passes = [&](double inc, const Eigen::VectorXd& xx) {
    return inc <= opts_.increment_rtol * weighted_max(xx - x_ref, w) + opts_.increment_atol;
  };
  for (int k = 0;; ++k) {
    // Tangent reuse (modified Newton): assemble the matrix only when a new
    // factorisation will be needed.
    const bool reuse = opts_.reuse_factorization && factor_valid_ && factor_key_ == tangent_key && !refactor_next_;
    // G (with `residual`; else the residual goes to a scratch vector, so a
    // tangent-only evaluation leaves G as it was) and K_ (with `tangent`) at
    // the iterate; false (reason set) when the system reports a numerical
    // error there.
    auto evaluate_iterate = [&](bool tangent, bool residual) {
      auto ta = Clock::now();
      try {
        sys_.evaluate(x, residual ? G : G_tangent, tangent ? &K_ : nullptr);
        if (sys_.pattern_revision() != pattern_revision_) sync_pattern();
      } catch (const common::NumericalError& e) {
        stats_.assembly_s += since(ta);
        factor_valid_ = false;
        res.reason = e.what();
        return false;
      }
      stats_.assembly_s += since(ta);
      if (tangent) have_K = true;
      return true;
    };
    if (!evaluated) {
      const bool tangent = !reuse && !(k > 0 && increment_passes(last_inc, x));
      have_K = false;
      if (!evaluate_iterate(tangent, true)) return res;
    }
    evaluated = false;
    const double r = constrained_norm(G);
    res.last_residual = r;
    res.residual_norms.push_back(r);
    if (!std::isfinite(r)) {
      res.reason = "non-finite residual";
      return res;
    }
    if (k == 0) r_ref = r;
    const bool res_ok = r <= std::max(opts_.residual_rtol * r_ref, opts_.residual_atol);
    const bool inc_ok = (k == 0) ? r <= opts_.residual_atol : increment_passes(last_inc, x);
    const bool roundoff = k > 0 && !res_ok && last_inc <= opts_.roundoff_increment_rel * x_scale_ &&
                          r <= opts_.roundoff_residual_drop * r_ref;
    // Load-relative pair (set_load_criterion): residual against the applied
    // load, increment against the solution's distance from its reference.
    bool load_ok = false;
    if (load_tol_ > 0 && r <= load_tol_ * load_norm_) {
      if (k == 0) {
        load_ok = true;  // the start point already balances the load
      } else {
        const double sol = x_solution_ref_.size() == n ? weighted_max(x - x_solution_ref_, w) : 0.0;
        load_ok = last_inc <= load_tol_ * sol;
      }
    }
    if (opts_.linear && k >= 1) {  // one solve, accepted as it is
      res.converged = true;
      return res;
    }
    if ((res_ok && inc_ok) || load_ok || roundoff) {
      if (roundoff) ++stats_.roundoff_acceptances;
      res.converged = true;
      return res;
    }
    if (k >= opts_.max_iterations) {
      factor_valid_ = false;
      std::ostringstream s;
      int worst = 0;
      const double worst_G = G.cwiseAbs().maxCoeff(&worst);
      s << "Newton did not converge in " << opts_.max_iterations << " iterations (residual " << r << " "
        << opts_.residual_unit << ", first " << r_ref << " " << opts_.residual_unit << ", last increment "
        << last_inc << " " << opts_.increment_unit << "; largest residual " << worst_G << " " << opts_.residual_unit
        << " at " << sys_.describe_dof(worst) << ")";
      res.reason = s.str();
      return res;
    }
    // Not converged after all: the tangent at this iterate.
    if (!reuse && !have_K && !evaluate_iterate(true, false)) return res;
    if (reuse && k > 0 && r > opts_.refactor_ratio * res.residual_norms[k - 1]) {
      // Contraction too slow with the old factorisation: re-evaluate the
      // tangent at this iterate and refactorise.
      if (!evaluate_iterate(true, false)) return res;
      refactor_next_ = true;
    }
    if (!reuse || refactor_next_) {
      if (!have_K) throw common::NumericalError("Newton: internal error: no tangent to factorise");
      constrain_matrix(K_);
      if (!factorize(K_, res.reason)) {
        factor_valid_ = false;
        return res;
      }
      factor_valid_ = true;
      factor_key_ = tangent_key;
      refactor_next_ = false;
    }
    auto ts = Clock::now();
    dx = solver_->solve(-G);
    stats_.solve_s += since(ts);
    ++stats_.iterations;
    if (!dx.allFinite()) {
      res.reason = "non-finite Newton increment";
      return res;
    }
    for (int i = 0; i < n; ++i)
      if (c[i]) dx(i) = 0;
    if (opts_.line_search_halvings > 0 && !opts_.reuse_factorization) {
      // Backtracking on the residual norm: the full step is tried with its
      // tangent (kept for the next iteration when accepted); shorter steps
      // need the residual only. Accept the first step with
      // ||G(x + s dx)|| <= (1 - 1e-4 s) ||G(x)||, else the last one tried.
      double s = 1.0;
      Eigen::VectorXd xt, Gt;
      bool full_tangent = false;
      for (int ls = 0;; ++ls) {
        xt = x + s * dx;
        if (ls == 0) full_tangent = !increment_passes(weighted_max(dx, w), xt);
        auto ta = Clock::now();
        double rt_norm = std::numeric_limits<double>::infinity();
        try {
          sys_.evaluate(xt, Gt, ls == 0 && full_tangent ? &K_ : nullptr);
          if (sys_.pattern_revision() != pattern_revision_) sync_pattern();
          rt_norm = constrained_norm(Gt);
        } catch (const common::NumericalError&) {
          // a trial outside the admissible region: shorten the step
        }
        stats_.assembly_s += since(ta);
        if (ls == 0) have_K = full_tangent && std::isfinite(rt_norm);
        const bool decrease = std::isfinite(rt_norm) && rt_norm <= (1 - 1e-4 * s) * r;
        if (decrease || ls >= opts_.line_search_halvings) {
          if (!std::isfinite(rt_norm)) {
            res.reason = "non-finite residual on every line-search trial";
            return res;
          }
          x = xt;
          G = Gt;
          evaluated = ls == 0;  // the full step's evaluation (with the tangent if have_K)
          if (ls > 0) ++stats_.line_search_reductions;
          break;
        }
        s *= 0.5;
      }
      last_inc = weighted_max(s * dx, w);
    } else {
      x += dx;
      last_inc = weighted_max(dx, w);
    }
    res.increment_norms.push_back(last_inc);
  }
}

}  // namespace arthrosim::numerics
