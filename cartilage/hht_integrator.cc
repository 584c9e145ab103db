#include "cartilage/hht_integrator.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>
#include <sstream>

#include "common/error.h"

namespace arthrosim::cartilage {
namespace {

using Clock = std::chrono::steady_clock;
double since(Clock::time_point t0) { return std::chrono::duration<double>(Clock::now() - t0).count(); }

double weighted_max(const Eigen::VectorXd& x, const Eigen::VectorXd& w) {
  return (x.cwiseAbs().cwiseProduct(w)).maxCoeff();
}

}  // namespace

HhtIntegrator::HhtIntegrator(TimeIntegrable& system, const IntegratorOptions& options)
    : sys_(system), opts_(options) {
  if (!(opts_.alpha >= -1.0 / 3.0 - 1e-15 && opts_.alpha <= 0))
    throw common::InputError("HHT: alpha must be in [-1/3, 0], found " + std::to_string(opts_.alpha));
  if (!(opts_.dt_s > 0)) throw common::InputError("HHT: dt must be > 0 s, found " + std::to_string(opts_.dt_s));
  if (opts_.max_newton_iterations < 1 || opts_.max_halvings < 0)
    throw common::InputError("HHT: max_newton_iterations >= 1 and max_halvings >= 0 required");
  if (!(opts_.min_step_fraction > 0 && opts_.min_step_fraction < 1))
    throw common::InputError("HHT: min_step_fraction must be in (0, 1), found " + std::to_string(opts_.min_step_fraction));
  if (!opts_.quasi_static && !sys_.has_inertia())
    throw common::InputError("HHT: dynamic integration needs an inertia term (or set quasi_static)");
  gamma_ = 0.5 - opts_.alpha;
  beta_ = 0.25 * (1 - opts_.alpha) * (1 - opts_.alpha);
  dt_ = opts_.dt_s;
  sync_pattern();
  LinearSolverKind kind = LinearSolverKind::kUmfpack;
  if (opts_.solver == LinearSolverChoice::kCholmod ||
      (opts_.solver == LinearSolverChoice::kAuto && sys_.tangent_symmetric()))
    kind = LinearSolverKind::kCholmod;
  solver_ = std::make_unique<SparseDirectSolver>(kind);
  stats_.linear_solver = to_string(kind);
}

void HhtIntegrator::sync_pattern() {
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
  // The transpose map (CHOLMOD on the symmetric part) is rebuilt when it is
  // needed: with UMFPACK it never is, and the walks change the pattern
  // dozens of times (2 % of a walk's time went into this map).
  transpose_index_.clear();
  if (solver_ && pattern_revision_ != sys_.pattern_revision()) {
    // A new pattern needs a new symbolic analysis (counted when it is done).
    solver_ = std::make_unique<SparseDirectSolver>(solver_->kind());
    factor_valid_ = false;
    ++stats_.pattern_changes;
  }
  pattern_revision_ = sys_.pattern_revision();
}

void HhtIntegrator::build_transpose_index() {
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
      if (it == end || *it != j) throw common::InputError("HHT: tangent pattern is not structurally symmetric");
      transpose_index_[k] = static_cast<int>(it - P.innerIndexPtr());
    }
}

HhtIntegrator::~HhtIntegrator() = default;

void HhtIntegrator::constrain_matrix(Eigen::SparseMatrix<double>& K) const {
  double* v = K.valuePtr();
  for (int k : zero_index_) v[k] = 0;
  for (int k : diag_index_) v[k] = 1;
}

bool HhtIntegrator::factorize(Eigen::SparseMatrix<double>& K, std::string& reason) {
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

void HhtIntegrator::initialize(double t0, const Eigen::VectorXd& q0, const Eigen::VectorXd& v0) {
  const int n = sys_.num_dofs();
  if (q0.size() != n) throw common::InputError("HHT: initial q has size " + std::to_string(q0.size()) + ", expected " + std::to_string(n));
  t_ = t0;
  q_ = q0;
  sys_.apply_constraints(t_, q_);
  v_ = v0.size() == n ? v0 : Eigen::VectorXd::Zero(n);
  a_ = Eigen::VectorXd::Zero(n);
  h_prev_ = 0;
  q_scale_ = 0;
  for (int i = 0; i < n; ++i)
    q_scale_ = std::max(q_scale_, std::abs(sys_.increment_weights()(i) * q_(i)));
  if (q_scale_ == 0) q_scale_ = 1.0;
  const auto& c = sys_.constrained();
  for (int i = 0; i < n; ++i)
    if (c[i]) v_(i) = 0;
  EvalRequest req;
  req.t = t_;
  req.q = &q_;
  req.v = opts_.quasi_static ? nullptr : &v_;
  auto ta = Clock::now();
  sys_.evaluate(req, F_, nullptr, nullptr);
  stats_.assembly_s += since(ta);
  if (!opts_.quasi_static) {
    sys_.solve_mass(-F_, a_);
    if (!a_.allFinite()) throw common::NumericalError("HHT: non-finite initial acceleration at t = " + std::to_string(t_));
  }
  stats_.status = IntegratorStatus::kRunning;
}

bool HhtIntegrator::attempt(double h, std::string& reason, double& last_residual) {
  const int n = sys_.num_dofs();
  const auto& c = sys_.constrained();
  const double t1 = t_ + h;
  Eigen::VectorXd q = q_, v = v_, a = a_, F, Ma, G, dq;
  if (opts_.predictor == IntegratorOptions::Predictor::kSystemExtrapolated && h_prev_ > 0)
    sys_.predict_extrapolated(t_ - h_prev_, q_ - dq_prev_, t_, q_, t1, q);
  else if (opts_.predictor != IntegratorOptions::Predictor::kPrevious)
    sys_.predict(t_, t1, q_, q);
  else if (opts_.quasi_static && opts_.extrapolate_predictor && h_prev_ > 0)
    q += (h / h_prev_) * dq_prev_;
  sys_.apply_constraints(t1, q);
  const double ka = 1.0 / (beta_ * h * h), kv = gamma_ / (beta_ * h);
  // Newmark relations: a and v of the iterate q.
  auto newmark = [&](const Eigen::VectorXd& qq, Eigen::VectorXd& aa, Eigen::VectorXd& vv) {
    if (opts_.quasi_static) return;
    aa = ka * (qq - q_ - h * v_) - (0.5 / beta_ - 1.0) * a_;
    vv = v_ + h * ((1 - gamma_) * a_ + gamma_ * aa);
  };
  auto request = [&](const Eigen::VectorXd& qq, const Eigen::VectorXd& vv, const Eigen::VectorXd& aa) {
    EvalRequest req;
    req.t = t1;
    req.q = &qq;
    req.v = opts_.quasi_static ? nullptr : &vv;
    req.a = opts_.quasi_static ? nullptr : &aa;
    req.force_scale = opts_.quasi_static ? 1.0 : 1.0 + opts_.alpha;
    req.kq = 1.0;
    req.kv = opts_.quasi_static ? 0.0 : kv;
    req.ka = opts_.quasi_static ? 0.0 : ka;
    return req;
  };
  // Residual of the step equation from F (and M a), constrained rows zeroed.
  auto residual = [&](const Eigen::VectorXd& FF, const Eigen::VectorXd& MMa, Eigen::VectorXd& GG) {
    GG = opts_.quasi_static ? FF : Eigen::VectorXd(MMa + (1 + opts_.alpha) * FF - opts_.alpha * F_);
    for (int i = 0; i < n; ++i)
      if (c[i]) GG(i) = 0;
    return GG.norm();
  };
  StepRecord rec;
  rec.t_start = t_;
  rec.dt = h;
  double r_ref = 0, last_inc = std::numeric_limits<double>::infinity();
  const Eigen::VectorXd& w = sys_.increment_weights();
  bool evaluated = false;  // F, Ma (and K_ if have_K) already hold the iterate (line search)
  bool have_K = false;
  // The increment test of an iterate is known before it is evaluated. An
  // iterate whose increment passes it is the converged one as soon as its
  // residual passes too, so it is evaluated without the tangent first (the
  // tangent is assembled after all only if Newton goes on from it): one
  // tangent assembly less per step.
  auto increment_passes = [&](double inc, const Eigen::VectorXd& qq) {
    return inc <= opts_.increment_rtol * weighted_max(qq - q_, w) + opts_.increment_atol_m;
  };
  for (int k = 0;; ++k) {
    newmark(q, a, v);
    const EvalRequest req = request(q, v, a);
    // Tangent reuse (modified Newton): assemble the matrix only when a new
    // factorisation will be needed.
    const bool reuse = opts_.reuse_factorization && factor_valid_ && factor_h_ == h && !refactor_next_;
    // F (and M a, and K_ with `tangent`) at the iterate; false (reason set)
    // when the system reports a numerical error there.
    auto evaluate_iterate = [&](bool tangent) {
      auto ta = Clock::now();
      try {
        sys_.evaluate(req, F, opts_.quasi_static ? nullptr : &Ma, tangent ? &K_ : nullptr);
        if (sys_.pattern_revision() != pattern_revision_) sync_pattern();
      } catch (const common::NumericalError& e) {
        stats_.assembly_s += since(ta);
        factor_valid_ = false;
        reason = e.what();
        return false;
      }
      stats_.assembly_s += since(ta);
      if (tangent) have_K = true;
      return true;
    };
    if (!evaluated) {
      const bool tangent = !reuse && !(k > 0 && increment_passes(last_inc, q));
      have_K = false;
      if (!evaluate_iterate(tangent)) return false;
    }
    evaluated = false;
    const double r = residual(F, Ma, G);
    last_residual = r;
    rec.residual_norms.push_back(r);
    if (!std::isfinite(r)) {
      reason = "non-finite residual";
      return false;
    }
    if (k == 0) r_ref = r;
    const bool res_ok = r <= std::max(opts_.residual_rtol * r_ref, opts_.residual_atol_N);
    const bool inc_ok = (k == 0) ? r <= opts_.residual_atol_N : increment_passes(last_inc, q);
    const bool roundoff = k > 0 && !res_ok && last_inc <= opts_.roundoff_increment_rel * q_scale_ &&
                          r <= opts_.roundoff_residual_drop * r_ref;
    if ((res_ok && inc_ok) || roundoff) {
      if (roundoff) ++stats_.roundoff_acceptances;
      dq_prev_ = q - q_;
      h_prev_ = h;
      t_ = t1;
      q_ = q;
      v_ = opts_.quasi_static ? Eigen::VectorXd::Zero(n) : v;
      a_ = opts_.quasi_static ? Eigen::VectorXd::Zero(n) : a;
      F_ = F;
      ++stats_.steps;
      if (opts_.keep_step_log) stats_.log.push_back(std::move(rec));
      return true;
    }
    if (k >= opts_.max_newton_iterations) {
      factor_valid_ = false;
      std::ostringstream s;
      int worst = 0;
      const double worst_N = G.cwiseAbs().maxCoeff(&worst);
      s << "Newton did not converge in " << opts_.max_newton_iterations << " iterations (residual " << r
        << " N, first " << r_ref << " N, last increment " << last_inc << " m; largest residual " << worst_N
        << " N at " << sys_.describe_dof(worst) << ")";
      reason = s.str();
      return false;
    }
    // Not converged after all: the tangent at this iterate.
    if (!reuse && !have_K && !evaluate_iterate(true)) return false;
    if (reuse && k > 0 && r > opts_.refactor_ratio * rec.residual_norms[k - 1]) {
      // Contraction too slow with the old factorisation: re-evaluate the
      // tangent at this iterate and refactorise.
      if (!evaluate_iterate(true)) return false;
      refactor_next_ = true;
    }
    if (!reuse || refactor_next_) {
      if (!have_K) throw common::NumericalError("HHT: internal error: no tangent to factorise");
      constrain_matrix(K_);
      if (!factorize(K_, reason)) {
        factor_valid_ = false;
        return false;
      }
      factor_valid_ = true;
      factor_h_ = h;
      refactor_next_ = false;
    }
    auto ts = Clock::now();
    dq = solver_->solve(-G);
    stats_.solve_s += since(ts);
    ++stats_.newton_iterations;
    if (!dq.allFinite()) {
      reason = "non-finite Newton increment";
      return false;
    }
    for (int i = 0; i < n; ++i)
      if (c[i]) dq(i) = 0;
    if (opts_.line_search_halvings > 0 && !opts_.reuse_factorization) {
      // Backtracking on the residual norm: the full step is tried with its
      // tangent (kept for the next iteration when accepted); shorter steps
      // need the residual only. Accept the first step with
      // ||G(q + s dq)|| <= (1 - 1e-4 s) ||G(q)||, else the last one tried.
      double s = 1.0;
      Eigen::VectorXd qt, vt = v, at = a, Ft, Mat, Gt;
      bool full_tangent = false;
      for (int ls = 0;; ++ls) {
        qt = q + s * dq;
        newmark(qt, at, vt);
        const EvalRequest rt = request(qt, vt, at);
        if (ls == 0) full_tangent = !increment_passes(weighted_max(dq, w), qt);
        auto ta = Clock::now();
        double rt_norm = std::numeric_limits<double>::infinity();
        try {
          sys_.evaluate(rt, Ft, opts_.quasi_static ? nullptr : &Mat, ls == 0 && full_tangent ? &K_ : nullptr);
          if (sys_.pattern_revision() != pattern_revision_) sync_pattern();
          rt_norm = residual(Ft, Mat, Gt);
        } catch (const common::NumericalError&) {
          // a trial outside the admissible region: shorten the step
        }
        stats_.assembly_s += since(ta);
        if (ls == 0) have_K = full_tangent && std::isfinite(rt_norm);
        const bool decrease = std::isfinite(rt_norm) && rt_norm <= (1 - 1e-4 * s) * r;
        if (decrease || ls >= opts_.line_search_halvings) {
          if (!std::isfinite(rt_norm)) {
            reason = "non-finite residual on every line-search trial";
            return false;
          }
          q = qt;
          F = Ft;
          Ma = Mat;
          evaluated = ls == 0;  // the full step's evaluation (with the tangent if have_K)
          if (ls > 0) ++stats_.line_search_reductions;
          break;
        }
        s *= 0.5;
      }
      last_inc = weighted_max(s * dq, w);
    } else {
      q += dq;
      last_inc = weighted_max(dq, w);
    }
    rec.increment_norms.push_back(last_inc);
  }
}

void HhtIntegrator::advance_to(double t_end) {
  if (stats_.status == IntegratorStatus::kNotStarted)
    throw common::InputError("HHT: initialize() must be called before advance_to()");
  auto t0 = Clock::now();
  int halvings = 0;
  // Tolerance on reaching t_end: a billionth of the nominal step.
  while (t_end - t_ > 1e-9 * opts_.dt_s) {
    const double h = std::min(dt_, t_end - t_);
    std::string reason;
    double r = 0;
    if (attempt(h, reason, r)) {
      halvings = 0;
      if (dt_ < opts_.dt_s && ++successes_since_halving_ >= opts_.steps_before_growth) {
        dt_ = std::min(2 * dt_, opts_.dt_s);
        successes_since_halving_ = 0;
      }
      continue;
    }
    ++stats_.rejected_steps;
    std::ostringstream s;
    s << "t=" << t_ << " s, dt=" << h << " s: " << reason;
    stats_.rejections.push_back(s.str());
    if (opts_.on_rejection) opts_.on_rejection(stats_.rejections.back());
    // Give up after max_halvings consecutive halvings, or when a step no
    // longer than min_step_fraction dt_s fails: otherwise rare successes of
    // ever shorter steps (each resetting the count) could creep on without end.
    const bool floor = h <= opts_.min_step_fraction * opts_.dt_s;
    if (++halvings > opts_.max_halvings || floor) {
      stats_.status = IntegratorStatus::kFailed;
      stats_.total_s += since(t0);
      std::ostringstream m;
      m << "HHT: step from t = " << t_ << " s failed after " << halvings << " consecutive halvings"
        << (floor ? " (the step reached the floor min_step_fraction x dt)" : std::string()) << " (last dt " << h
        << " s, residual " << r << " N): " << reason;
      throw common::NumericalError(m.str());
    }
    dt_ = 0.5 * h;
    successes_since_halving_ = 0;
  }
  stats_.total_s += since(t0);
}

bool HhtIntegrator::advance_to_steady_state(double change_tol_m, double t_max, double* last_change_m) {
  if (!(change_tol_m > 0)) throw common::InputError("HHT: steady-state change tolerance must be > 0 m");
  const Eigen::VectorXd& w = sys_.increment_weights();
  double change = std::numeric_limits<double>::infinity();
  while (t_max - t_ > 1e-9 * opts_.dt_s) {
    const Eigen::VectorXd q_before = q_;
    const double h = std::min(opts_.dt_s, t_max - t_);
    advance_to(t_ + h);
    change = weighted_max(q_ - q_before, w);
    if (last_change_m) *last_change_m = change;
    // Only a whole step of dt_s measures the change per step.
    if (change <= change_tol_m && h >= (1 - 1e-9) * opts_.dt_s) return true;
  }
  return false;
}

}  // namespace arthrosim::cartilage
