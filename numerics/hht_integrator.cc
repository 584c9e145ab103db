#include "numerics/hht_integrator.h"

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

void IntegratorOptions::declare(common::OptionVisitor& v) {
  using common::Unit;
  v.number("time_step_s", dt_s, Unit::kSecond, {1e-8, 1}, "HHT time step");
  v.number("hht_alpha", alpha, Unit::kNone, {-1.0 / 3.0, 0}, "HHT numerical damping parameter (0 = trapezoidal rule)");
  v.integer("max_newton_iterations", max_newton_iterations, {1, 1000},
            "Newton iterations per step attempt before the step is halved");
  v.number("newton_tolerance", residual_rtol, Unit::kNone, {1e-14, 1e-2},
           "relative tolerance of a step's Newton iteration on the residual and on the increment "
           "(docs/shell_element.md)");
  v.number("newton_residual_floor_n", residual_atol_N, Unit::kNone, {0, 1e6},
           "absolute residual [N] below which a step's residual test passes whatever its first residual "
           "(contact: force jumps at facet kinks leave residuals of order 0.01 N)");
  v.number("newton_increment_floor_mm", increment_atol_m, Unit::kMillimetre, {0, 1},
           "absolute Newton increment below which a step's increment test passes");
  v.number("newton_load_tolerance", load_rtol, Unit::kNone, {0, 1e-2},
           "> 0: a step also converges when its residual is at most this times the norm of the applied load (loads "
           "and forces of prescribed motion on the free coordinates at the step's time) and its increment at most this "
           "times the solution's largest distance from the initial state (docs/shell_element.md); 0: off");
  v.choice("linear_solver", solver,
           {{"auto", LinearSolverChoice::kAuto},
            {"cholmod", LinearSolverChoice::kCholmod},
            {"umfpack", LinearSolverChoice::kUmfpack}},
           "sparse solver of the Newton steps: auto (CHOLMOD when every tangent is symmetric, else UMFPACK), cholmod "
           "(on the symmetric part (K + K^T)/2), umfpack");
  v.flag("newton_reuse_factorization", reuse_factorization,
         "modified Newton: keep the last factorisation across iterations and steps of the same size while the residual "
         "falls by 4x per iteration (else refactorise); not with mesh_contact");
}

// The equation of one step as a Newton system in q_{n+1} (file comment of
// hht_integrator.h): G = M a + (1 + alpha) F(q, v, t1) - alpha F_n with a, v
// from the Newmark relations, or G = F(q, 0, t1) quasi-statically. Keeps the
// F, M a, v and a of its last evaluation (the converged iterate's, when
// Newton stops there).
class HhtIntegrator::StepSystem final : public NewtonSystem {
 public:
  StepSystem(TimeIntegrable& sys, const HhtIntegrator& hht) : sys_(sys), hht_(hht) {}

  /// Starts the step from the accepted state of `hht_` to t1 = t + h.
  void begin(double t1, double h) {
    t1_ = t1;
    h_ = h;
    ka_ = 1.0 / (hht_.beta_ * h * h);
    kv_ = hht_.gamma_ / (hht_.beta_ * h);
    v_ = hht_.v_;
    a_ = hht_.a_;
  }
  const Eigen::VectorXd& F() const { return F_; }
  const Eigen::VectorXd& v() const { return v_; }
  const Eigen::VectorXd& a() const { return a_; }

  int size() const override { return sys_.num_dofs(); }
  void evaluate(const Eigen::VectorXd& q, Eigen::VectorXd& G, Eigen::SparseMatrix<double>* K) override {
    const IntegratorOptions& o = hht_.opts_;
    if (!o.quasi_static) {
      a_ = ka_ * (q - hht_.q_ - h_ * hht_.v_) - (0.5 / hht_.beta_ - 1.0) * hht_.a_;
      v_ = hht_.v_ + h_ * ((1 - hht_.gamma_) * hht_.a_ + hht_.gamma_ * a_);
    }
    EvalRequest req;
    req.t = t1_;
    req.q = &q;
    req.v = o.quasi_static ? nullptr : &v_;
    req.a = o.quasi_static ? nullptr : &a_;
    req.force_scale = o.quasi_static ? 1.0 : 1.0 + o.alpha;
    req.kq = 1.0;
    req.kv = o.quasi_static ? 0.0 : kv_;
    req.ka = o.quasi_static ? 0.0 : ka_;
    sys_.evaluate(req, F_, o.quasi_static ? nullptr : &Ma_, K);
    G = o.quasi_static ? F_ : Eigen::VectorXd(Ma_ + (1 + o.alpha) * F_ - o.alpha * hht_.F_);
  }
  const Eigen::SparseMatrix<double>& tangent_pattern() const override { return sys_.tangent_pattern(); }
  long pattern_revision() const override { return sys_.pattern_revision(); }
  bool tangent_symmetric() const override { return sys_.tangent_symmetric(); }
  const std::vector<char>& constrained() const override { return sys_.constrained(); }
  const Eigen::VectorXd& increment_weights() const override { return sys_.increment_weights(); }
  std::string describe_dof(int i) const override { return sys_.describe_dof(i); }

 private:
  TimeIntegrable& sys_;
  const HhtIntegrator& hht_;
  double t1_ = 0, h_ = 0, ka_ = 0, kv_ = 0;
  Eigen::VectorXd F_, Ma_, v_, a_;
};

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
  NewtonOptions no;
  no.max_iterations = opts_.max_newton_iterations;
  no.residual_rtol = opts_.residual_rtol;
  no.residual_atol = opts_.residual_atol_N;
  no.increment_rtol = opts_.increment_rtol;
  no.increment_atol = opts_.increment_atol_m;
  no.roundoff_increment_rel = opts_.roundoff_increment_rel;
  no.roundoff_residual_drop = opts_.roundoff_residual_drop;
  no.reuse_factorization = opts_.reuse_factorization;
  no.refactor_ratio = opts_.refactor_ratio;
  no.line_search_halvings = opts_.line_search_halvings;
  no.linear = opts_.linear;
  no.solver = opts_.solver;
  step_ = std::make_unique<StepSystem>(sys_, *this);
  newton_ = std::make_unique<NewtonSolver>(*step_, no);
  copy_newton_statistics();
}

HhtIntegrator::~HhtIntegrator() = default;

void HhtIntegrator::copy_newton_statistics() {
  const NewtonStatistics& n = newton_->statistics();
  stats_.newton_iterations = n.iterations;
  stats_.factorizations = n.factorizations;
  stats_.symbolic_analyses = n.symbolic_analyses;
  stats_.solver_switches = n.solver_switches;
  stats_.pattern_changes = n.pattern_changes;
  stats_.line_search_reductions = n.line_search_reductions;
  stats_.roundoff_acceptances = n.roundoff_acceptances;
  stats_.assembly_s = initial_assembly_s_ + n.assembly_s;
  stats_.factorization_s = n.factorization_s;
  stats_.solve_s = n.solve_s;
  stats_.linear_solver = n.linear_solver;
}

void HhtIntegrator::initialize(double t0, const Eigen::VectorXd& q0, const Eigen::VectorXd& v0) {
  const int n = sys_.num_dofs();
  if (q0.size() != n) throw common::InputError("HHT: initial q has size " + std::to_string(q0.size()) + ", expected " + std::to_string(n));
  t_ = t0;
  q_ = q0;
  sys_.apply_constraints(t_, q_);
  q_initial_ = q_;
  v_ = v0.size() == n ? v0 : Eigen::VectorXd::Zero(n);
  a_ = Eigen::VectorXd::Zero(n);
  h_prev_ = 0;
  double q_scale = 0;
  for (int i = 0; i < n; ++i)
    q_scale = std::max(q_scale, std::abs(sys_.increment_weights()(i) * q_(i)));
  if (q_scale == 0) q_scale = 1.0;
  newton_->set_roundoff_scale(q_scale);
  const auto& c = sys_.constrained();
  for (int i = 0; i < n; ++i)
    if (c[i]) v_(i) = 0;
  EvalRequest req;
  req.t = t_;
  req.q = &q_;
  req.v = opts_.quasi_static ? nullptr : &v_;
  auto ta = Clock::now();
  sys_.evaluate(req, F_, nullptr, nullptr);
  initial_assembly_s_ += since(ta);
  copy_newton_statistics();
  if (!opts_.quasi_static) {
    sys_.solve_mass(-F_, a_);
    if (!a_.allFinite()) throw common::NumericalError("HHT: non-finite initial acceleration at t = " + std::to_string(t_));
  }
  stats_.status = IntegratorStatus::kRunning;
}

HhtState HhtIntegrator::state() const {
  HhtState s;
  s.t = t_;
  s.dt = dt_;
  s.h_prev = h_prev_;
  s.successes_since_halving = successes_since_halving_;
  s.q = q_;
  s.v = v_;
  s.a = a_;
  s.F = F_;
  s.q_initial = q_initial_;
  s.dq_prev = dq_prev_;
  s.steps = stats_.steps;
  s.rejected_steps = stats_.rejected_steps;
  s.rejections = stats_.rejections;
  s.newton = newton_->statistics();
  s.kept = newton_->kept_factorization();
  s.initial_assembly_s = initial_assembly_s_;
  s.total_s = stats_.total_s;
  return s;
}

void HhtIntegrator::restore(const HhtState& s) {
  const Eigen::Index n = sys_.num_dofs();
  for (const Eigen::VectorXd* v : {&s.q, &s.v, &s.a, &s.F, &s.q_initial})
    if (v->size() != n)
      throw common::InputError("HHT: restored state of size " + std::to_string(v->size()) + ", expected " +
                               std::to_string(n));
  if (stats_.status != IntegratorStatus::kRunning) throw common::InputError("HHT: restore() needs initialize() first");
  t_ = s.t;
  dt_ = s.dt;
  h_prev_ = s.h_prev;
  successes_since_halving_ = s.successes_since_halving;
  q_ = s.q;
  v_ = s.v;
  a_ = s.a;
  F_ = s.F;
  q_initial_ = s.q_initial;
  dq_prev_ = s.dq_prev;
  stats_.steps = s.steps;
  stats_.rejected_steps = s.rejected_steps;
  stats_.rejections = s.rejections;
  stats_.log.clear();
  stats_.total_s = s.total_s;
  initial_assembly_s_ = s.initial_assembly_s;
  newton_->restore_statistics(s.newton);
  newton_->restore_kept_factorization(s.kept);
  copy_newton_statistics();
}

bool HhtIntegrator::attempt(double h, std::string& reason, double& last_residual) {
  const int n = sys_.num_dofs();
  const double t1 = t_ + h;
  Eigen::VectorXd q = q_;
  if (opts_.predictor == IntegratorOptions::Predictor::kSystemExtrapolated && h_prev_ > 0)
    sys_.predict_extrapolated(t_ - h_prev_, q_ - dq_prev_, t_, q_, t1, q);
  else if (opts_.predictor != IntegratorOptions::Predictor::kPrevious)
    sys_.predict(t_, t1, q_, q);
  else if (opts_.quasi_static && opts_.extrapolate_predictor && h_prev_ > 0)
    q += (h / h_prev_) * dq_prev_;
  sys_.apply_constraints(t1, q);
  if (opts_.load_rtol > 0) {
    // The applied load at t1: F at the initial state with t1's constraints.
    Eigen::VectorXd q_load = q_initial_, F_load;
    sys_.apply_constraints(t1, q_load);
    EvalRequest req;
    req.t = t1;
    req.q = &q_load;
    sys_.evaluate(req, F_load, nullptr, nullptr);
    const std::vector<char>& c = sys_.constrained();
    for (int i = 0; i < n; ++i)
      if (c[i]) F_load(i) = 0;
    newton_->set_load_criterion(opts_.load_rtol, F_load.norm(), q_initial_);
  }
  step_->begin(t1, h);
  NewtonResult r = newton_->solve(q, q_, h);
  copy_newton_statistics();
  last_residual = r.last_residual;
  if (!r.converged) {
    reason = r.reason;
    return false;
  }
  const double t0 = t_;
  dq_prev_ = q - q_;
  h_prev_ = h;
  t_ = t1;
  q_ = q;
  v_ = opts_.quasi_static ? Eigen::VectorXd::Zero(n) : step_->v();
  a_ = opts_.quasi_static ? Eigen::VectorXd::Zero(n) : step_->a();
  F_ = step_->F();
  ++stats_.steps;
  if (opts_.keep_step_log) {
    StepRecord rec;
    rec.t_start = t0;
    rec.dt = h;
    rec.residual_norms = std::move(r.residual_norms);
    rec.increment_norms = std::move(r.increment_norms);
    stats_.log.push_back(std::move(rec));
  }
  return true;
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

}  // namespace arthrosim::numerics
