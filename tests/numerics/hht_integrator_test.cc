// HHT-alpha on a single-DOF linear oscillator m u'' + k u = 0: the simulated
// period elongation and numerical damping match the spectral analysis of the
// HHT recurrence (Hilber, Hughes & Taylor 1977; Hughes, The Finite Element
// Method, 1987, ch. 9), alpha = 0 conserves energy, and step halving /
// failure reporting work.
#include <gtest/gtest.h>

#include <cstdint>
#include <cstring>

#include <Eigen/Eigenvalues>
#include <cmath>
#include <complex>
#include <cstdio>

#include "numerics/hht_integrator.h"
#include "common/error.h"

namespace arthrosim::numerics {
namespace {

// The bits of a double, for bit-for-bit comparisons.
std::uint64_t bits(double x) {
  std::uint64_t u;
  std::memcpy(&u, &x, sizeof u);
  return u;
}

/// m u'' + k u + c_cubic u^3 = 0 (c_cubic = 0: linear oscillator).
class Oscillator final : public TimeIntegrable {
 public:
  Oscillator(double m, double k, double cubic = 0) : m_(m), k_(k), cubic_(cubic) {
    std::vector<Eigen::Triplet<double>> t{{0, 0, 0.0}};
    pattern_.resize(1, 1);
    pattern_.setFromTriplets(t.begin(), t.end());
    pattern_.makeCompressed();
  }
  int num_dofs() const override { return 1; }
  bool has_inertia() const override { return true; }
  bool tangent_symmetric() const override { return true; }
  void evaluate(const EvalRequest& r, Eigen::VectorXd& F, Eigen::VectorXd* Ma, Eigen::SparseMatrix<double>* K) override {
    const double u = (*r.q)(0);
    if (fail_above_ > 0 && std::abs(u) > fail_above_) throw common::NumericalError("oscillator: |u| too large");
    F.resize(1);
    F(0) = k_ * u + cubic_ * u * u * u;
    if (Ma) {
      Ma->resize(1);
      (*Ma)(0) = r.a ? m_ * (*r.a)(0) : 0.0;
    }
    ++evaluations_;
    if (K) {
      ++tangent_evaluations_;
      *K = pattern_;
      K->valuePtr()[0] = r.force_scale * r.kq * (k_ + 3 * cubic_ * u * u) + r.ka * m_;
    }
  }
  const Eigen::SparseMatrix<double>& tangent_pattern() const override { return pattern_; }
  const std::vector<char>& constrained() const override { return constrained_; }
  void apply_constraints(double, Eigen::VectorXd&) const override {}
  void solve_mass(const Eigen::VectorXd& rhs, Eigen::VectorXd& a) override { a = rhs / m_; }
  const Eigen::VectorXd& increment_weights() const override { return weights_; }
  std::string describe_dof(int) const override { return "u"; }
  double fail_above_ = 0;
  long evaluations_ = 0, tangent_evaluations_ = 0;

 private:
  double m_, k_, cubic_;
  Eigen::SparseMatrix<double> pattern_;
  std::vector<char> constrained_{0};
  Eigen::VectorXd weights_ = Eigen::VectorXd::Ones(1);
};

/// Spectral reference: the HHT step for m u'' + k u = 0 is linear in
/// (u, h v, h^2 a); build its amplification matrix from the three HHT
/// equations (written out here independently of the integrator) and return
/// the principal eigenvalue.
std::complex<double> principal_eigenvalue(double alpha, double Omega) {
  const double gamma = 0.5 - alpha, beta = 0.25 * (1 - alpha) * (1 - alpha);
  const double w2 = Omega * Omega;  // (omega h)^2, with m = 1, k = omega^2, h = 1 units
  Eigen::Matrix3d A;
  for (int j = 0; j < 3; ++j) {
    Eigen::Vector3d x = Eigen::Vector3d::Zero();  // (u, v, a) with h = 1
    x(j) = 1;
    // a1 (1 + (1+alpha) w2 beta) = -w2 u - (1+alpha) w2 (v + (1/2 - beta) a)
    const double a1 = (-w2 * x(0) - (1 + alpha) * w2 * (x(1) + (0.5 - beta) * x(2))) / (1 + (1 + alpha) * w2 * beta);
    const double u1 = x(0) + x(1) + (0.5 - beta) * x(2) + beta * a1;
    const double v1 = x(1) + (1 - gamma) * x(2) + gamma * a1;
    A.col(j) << u1, v1, a1;
  }
  Eigen::EigenSolver<Eigen::Matrix3d> es(A);
  std::complex<double> best(0, 0);
  for (int i = 0; i < 3; ++i)
    if (std::abs(es.eigenvalues()(i).imag()) > std::abs(best.imag())) best = es.eigenvalues()(i);
  return best;
}

struct Measured {
  double period_ratio;  // numerical period / exact period
  double damping;       // numerical damping ratio xi
};

/// Simulates u(0) = 1, v(0) = 0 over `periods` periods with `steps_per_period`
/// and measures the period (from upward zero crossings, linearly
/// interpolated) and the logarithmic decrement of successive maxima.
Measured simulate(double alpha, int steps_per_period, int periods) {
  const double T = 1.0, omega = 2 * M_PI / T;
  Oscillator osc(1.0, omega * omega);
  IntegratorOptions o;
  o.alpha = alpha;
  o.dt_s = T / steps_per_period;
  o.keep_step_log = false;
  HhtIntegrator hht(osc, o);
  hht.initialize(0, Eigen::VectorXd::Ones(1));
  std::vector<double> crossings, peaks;
  double u_prev = 1, t_prev = 0, du_prev = 0;
  for (int n = 1; n <= steps_per_period * periods; ++n) {
    hht.advance_to(n * o.dt_s);
    const double u = hht.q()(0), t = hht.time();
    if (u_prev < 0 && u >= 0) crossings.push_back(t_prev + (t - t_prev) * (-u_prev) / (u - u_prev));
    const double du = u - u_prev;
    if (du_prev > 0 && du <= 0) peaks.push_back(u_prev);
    du_prev = du;
    u_prev = u;
    t_prev = t;
  }
  const double period = (crossings.back() - crossings.front()) / (crossings.size() - 1);
  // Discrete peaks: use amplitude envelope via energy-like ratio of peaks
  // separated by many periods (sampling error of a peak is O(Omega^2), same
  // at both ends, cancels in the ratio).
  const double ratio = peaks.back() / peaks.front();
  const double cycles = static_cast<double>(peaks.size() - 1);
  const double omega_bar = 2 * M_PI / period;
  // |lambda|^N = exp(-xi omega_bar t): xi = -ln(ratio) / (omega_bar * cycles * period).
  const double xi = -std::log(ratio) / (omega_bar * cycles * period);
  return {period / T, xi};
}

// For Omega = omega h = 2 pi / 20 and alpha in {0, -0.05, -0.2, -1/3}: the
// measured period ratio and damping ratio match the eigenvalue analysis
// (Omega_bar = arg(lambda), xi = -ln|lambda| / Omega_bar). For alpha = 0 the
// reference is also the closed form of the trapezoidal rule,
// Omega_bar = 2 atan(Omega/2), xi = 0. Tolerances: zero-crossing
// interpolation and peak sampling errors are O(Omega^2) ~ 1e-2 per event and
// do not accumulate; over 400 periods they give < 1e-5 in the period ratio
// and < 1e-5 absolute in xi (xi itself is 2e-4 .. 6e-4): we use 2e-5 and 4%.
TEST(Hht, PeriodElongationAndDampingMatchSpectralAnalysis) {
  const int spp = 20, periods = 400;
  const double Omega = 2 * M_PI / spp;
  for (double alpha : {0.0, -0.05, -0.2, -1.0 / 3.0}) {
    const std::complex<double> lam = principal_eigenvalue(alpha, Omega);
    const double Omega_bar = std::abs(std::arg(lam));
    const double xi_ref = -std::log(std::abs(lam)) / Omega_bar;
    const double period_ref = Omega / Omega_bar;
    const Measured m = simulate(alpha, spp, periods);
    std::printf("alpha=%.4f: period ratio %.7f (spectral %.7f), xi %.6f (spectral %.6f)\n", alpha, m.period_ratio,
                period_ref, m.damping, xi_ref);
    EXPECT_NEAR(m.period_ratio, period_ref, 2e-5);
    if (alpha == 0.0) {
      EXPECT_NEAR(period_ref, Omega / (2 * std::atan(Omega / 2)), 1e-12);
      EXPECT_NEAR(xi_ref, 0.0, 1e-12);
      EXPECT_NEAR(m.damping, 0.0, 1e-5);
    } else {
      EXPECT_NEAR(m.damping, xi_ref, 0.04 * xi_ref);
      EXPECT_GT(m.period_ratio, Omega / (2 * std::atan(Omega / 2)));  // more elongation than alpha = 0
    }
  }
}

// alpha = 0 (trapezoidal rule) conserves m v^2/2 + k u^2/2 exactly for a
// linear system (|lambda| = 1): after 50 periods the energy equals the
// initial one to round-off (1e-10 relative over 1000 steps).
TEST(Hht, AlphaZeroConservesEnergy) {
  const double omega = 2 * M_PI;
  Oscillator osc(2.0, 2.0 * omega * omega);
  IntegratorOptions o;
  o.alpha = 0.0;
  o.dt_s = 0.05;
  HhtIntegrator hht(osc, o);
  hht.initialize(0, Eigen::VectorXd::Constant(1, 0.3), Eigen::VectorXd::Constant(1, 0.7));
  auto energy = [&]() { return 0.5 * 2.0 * std::pow(hht.v()(0), 2) + 0.5 * 2.0 * omega * omega * std::pow(hht.q()(0), 2); };
  const double E0 = energy();
  hht.advance_to(50.0);
  std::printf("alpha=0: energy drift %.3e relative after %ld steps\n", energy() / E0 - 1, hht.statistics().steps);
  EXPECT_NEAR(energy() / E0, 1.0, 1e-10);
  // And with alpha < 0 the energy decays.
  o.alpha = -0.2;
  HhtIntegrator damped(osc, o);
  damped.initialize(0, Eigen::VectorXd::Constant(1, 0.3), Eigen::VectorXd::Constant(1, 0.7));
  damped.advance_to(50.0);
  const double Ed = 0.5 * 2.0 * std::pow(damped.v()(0), 2) + 0.5 * 2.0 * omega * omega * std::pow(damped.q()(0), 2);
  EXPECT_LT(Ed, 0.9 * E0);
}

// A failing evaluation (NumericalError inside the step) is rejected and the
// step halved; the rejections are counted; when halving cannot help the run
// stops with a NumericalError naming the time and the residual.
TEST(Hht, RejectionHalvingAndFailureReport) {
  Oscillator osc(1.0, 1.0, 50.0);  // stiffening spring: Newton needs several iterations
  IntegratorOptions o;
  o.alpha = -0.1;
  o.dt_s = 0.5;
  o.max_newton_iterations = 2;  // too few for the big step: forces halving
  HhtIntegrator hht(osc, o);
  hht.initialize(0, Eigen::VectorXd::Constant(1, 1.0));
  hht.advance_to(2.0);
  const auto& st = hht.statistics();
  std::printf("halving: %ld steps, %ld rejected, %ld Newton iterations\n", st.steps, st.rejected_steps,
              st.newton_iterations);
  EXPECT_GT(st.rejected_steps, 0);
  EXPECT_EQ(static_cast<long>(st.rejections.size()), st.rejected_steps);
  // Each rejection says why, with the coordinate of the largest residual.
  ASSERT_FALSE(st.rejections.empty());
  std::printf("first rejection: %s\n", st.rejections[0].c_str());
  EXPECT_NE(st.rejections[0].find("did not converge"), std::string::npos);
  EXPECT_NE(st.rejections[0].find(" N at u)"), std::string::npos);
  EXPECT_NEAR(hht.time(), 2.0, 1e-12);

  Oscillator bad(1.0, 1.0);
  bad.fail_above_ = 0.5;  // any state with |u| > 0.5 is "non-finite"
  IntegratorOptions ob;
  ob.dt_s = 0.1;
  ob.max_halvings = 3;
  HhtIntegrator hb(bad, ob);
  hb.initialize(0, Eigen::VectorXd::Constant(1, 0.45), Eigen::VectorXd::Constant(1, 1.0));
  try {
    hb.advance_to(1.0);
    FAIL() << "expected NumericalError";
  } catch (const common::NumericalError& e) {
    const std::string msg = e.what();
    std::printf("failure message: %s\n", msg.c_str());
    EXPECT_NE(msg.find("t = "), std::string::npos);
    EXPECT_NE(msg.find("residual"), std::string::npos);
    // One rejection may precede the fatal sequence; the last 3 + 1 attempts
    // at the failing time are all counted.
    EXPECT_GE(hb.statistics().rejected_steps, 4);
    EXPECT_EQ(hb.statistics().status, IntegratorStatus::kFailed);
  }
}

// Checkpoint and resume (docs/testing.md): the state taken mid-run and
// restored into a fresh integrator (after initialize) continues bit for bit,
// including the adaptive step size (halved here, growing back) and the
// counters.
TEST(Hht, RestoredStateContinuesBitIdentical) {
  IntegratorOptions o;
  o.alpha = -0.1;
  o.dt_s = 0.5;
  o.max_newton_iterations = 2;  // forces halvings, then growth back to dt_s
  Oscillator a_sys(1.0, 1.0, 50.0), b_sys(1.0, 1.0, 50.0), c_sys(1.0, 1.0, 50.0);
  const Eigen::VectorXd q0 = Eigen::VectorXd::Constant(1, 1.0);
  // The uninterrupted run makes the same advance_to calls (an advance_to
  // ends with a shortened step at its end time).
  HhtIntegrator a(a_sys, o);
  a.initialize(0, q0);
  a.advance_to(0.75);
  a.advance_to(3.0);
  HhtIntegrator b(b_sys, o);
  b.initialize(0, q0);
  b.advance_to(0.75);
  const HhtState mid = b.state();
  ASSERT_LT(mid.dt, o.dt_s);  // the step-size state matters at this point
  HhtIntegrator c(c_sys, o);
  c.initialize(0, q0);
  c.restore(mid);
  c.advance_to(3.0);
  EXPECT_EQ(bits(c.q()(0)), bits(a.q()(0)));
  EXPECT_EQ(bits(c.v()(0)), bits(a.v()(0)));
  EXPECT_EQ(bits(c.a()(0)), bits(a.a()(0)));
  EXPECT_EQ(bits(c.current_dt()), bits(a.current_dt()));
  EXPECT_EQ(c.statistics().steps, a.statistics().steps);
  EXPECT_EQ(c.statistics().rejected_steps, a.statistics().rejected_steps);
  EXPECT_EQ(c.statistics().newton_iterations, a.statistics().newton_iterations);
  EXPECT_EQ(c.statistics().rejections, a.statistics().rejections);
}

// Modified Newton (reuse_factorization): the state carries the kept
// factorisation (the matrix factorised and its key); restored into a fresh
// integrator the run continues bit for bit with the same factorisation count.
// Without it (the state's `kept` cleared) the fresh tangent changes the
// iterates: the comparison can fail. A strongly cubic oscillator with
// tolerances 1e-6, so the matrix Newton iterates with shows in the bits.
TEST(Hht, RestoredKeptFactorizationContinuesBitIdentical) {
  IntegratorOptions o;
  o.dt_s = 0.05;
  // Loose tolerances: the accepted iterate depends on the matrix Newton
  // iterated with, so leaving the kept factorisation out shows.
  o.residual_rtol = 1e-6;
  o.increment_rtol = 1e-6;
  o.reuse_factorization = true;
  Oscillator a_sys(1.0, 1.0, 500.0), b_sys(1.0, 1.0, 500.0), c_sys(1.0, 1.0, 500.0), d_sys(1.0, 1.0, 500.0);
  const Eigen::VectorXd q0 = Eigen::VectorXd::Constant(1, 0.5);
  HhtIntegrator a(a_sys, o);
  a.initialize(0, q0);
  a.advance_to(0.5);
  a.advance_to(1.0);
  HhtIntegrator b(b_sys, o);
  b.initialize(0, q0);
  b.advance_to(0.5);
  const HhtState mid = b.state();
  ASSERT_TRUE(mid.kept.valid);
  ASSERT_EQ(mid.kept.matrix.rows(), 1);
  HhtIntegrator c(c_sys, o);
  c.initialize(0, q0);
  c.restore(mid);
  c.advance_to(1.0);
  EXPECT_EQ(bits(c.q()(0)), bits(a.q()(0)));
  EXPECT_EQ(bits(c.v()(0)), bits(a.v()(0)));
  EXPECT_EQ(c.statistics().factorizations, a.statistics().factorizations);
  EXPECT_EQ(c.statistics().newton_iterations, a.statistics().newton_iterations);
  HhtState cleared = mid;
  cleared.kept = KeptFactorization();
  HhtIntegrator d(d_sys, o);
  d.initialize(0, q0);
  d.restore(cleared);
  d.advance_to(1.0);
  std::printf("uninterrupted: %ld factorisations, %ld iterations, q %.17g; resumed without the kept factorisation: "
              "%ld, %ld, q %.17g\n",
              a.statistics().factorizations, a.statistics().newton_iterations, a.q()(0), d.statistics().factorizations,
              d.statistics().newton_iterations, d.q()(0));
  EXPECT_NE(bits(d.q()(0)), bits(a.q()(0)));
  // A matrix of another pattern is refused, naming both.
  HhtState wrong = mid;
  wrong.kept.matrix.resize(2, 2);
  HhtIntegrator e(d_sys, o);
  e.initialize(0, q0);
  try {
    e.restore(wrong);
    FAIL() << "expected InputError";
  } catch (const common::InputError& err) {
    EXPECT_NE(std::string(err.what()).find("tangent pattern"), std::string::npos) << err.what();
  }
}

/// Quasi-static F(q, t) = atan(q - g(t)), g(t) = -log(1 - t): Newton from
/// the previous state converges only while g changes by less than about 1.4
/// per step, i.e. for steps shorter than about 1 - t: approaching t = 1 the
/// steps that succeed get ever shorter.
class ZenoSystem final : public TimeIntegrable {
 public:
  ZenoSystem() {
    std::vector<Eigen::Triplet<double>> t{{0, 0, 0.0}};
    pattern_.resize(1, 1);
    pattern_.setFromTriplets(t.begin(), t.end());
    pattern_.makeCompressed();
  }
  int num_dofs() const override { return 1; }
  bool has_inertia() const override { return false; }
  bool tangent_symmetric() const override { return true; }
  void evaluate(const EvalRequest& r, Eigen::VectorXd& F, Eigen::VectorXd*, Eigen::SparseMatrix<double>* K) override {
    const double e = (*r.q)(0) + std::log(1 - r.t);
    F.resize(1);
    F(0) = std::atan(e);
    if (K) {
      *K = pattern_;
      K->valuePtr()[0] = 1 / (1 + e * e);
    }
  }
  const Eigen::SparseMatrix<double>& tangent_pattern() const override { return pattern_; }
  const std::vector<char>& constrained() const override { return constrained_; }
  void apply_constraints(double, Eigen::VectorXd&) const override {}
  void solve_mass(const Eigen::VectorXd& rhs, Eigen::VectorXd& a) override { a = rhs; }
  const Eigen::VectorXd& increment_weights() const override { return weights_; }
  std::string describe_dof(int) const override { return "q"; }

 private:
  Eigen::SparseMatrix<double> pattern_;
  std::vector<char> constrained_{0};
  Eigen::VectorXd weights_ = Eigen::VectorXd::Ones(1);
};

// Steps that succeed only when ever shorter must not creep on: once a step
// no longer than min_step_fraction dt fails, the run stops with a message,
// after a bounded number of steps (each success resets the count of
// consecutive halvings).
TEST(Hht, EverShorterStepsStopAtTheStepFloor) {
  ZenoSystem sys;
  IntegratorOptions o;
  o.quasi_static = true;
  o.extrapolate_predictor = false;
  o.dt_s = 0.1;
  o.max_halvings = 30;  // the count of consecutive halvings must not be what stops it
  o.min_step_fraction = 1.0 / 256;
  o.max_newton_iterations = 8;
  // Every rejection reaches the caller at once, during the one advance_to().
  std::vector<std::string> reported;
  o.on_rejection = [&](const std::string& r) { reported.push_back(r); };
  HhtIntegrator hht(sys, o);
  hht.initialize(0, Eigen::VectorXd::Zero(1));
  try {
    hht.advance_to(1.0);
    FAIL() << "expected NumericalError";
  } catch (const common::NumericalError& e) {
    const std::string msg = e.what();
    std::printf("step floor: t = %.6f after %ld steps, %ld rejected: %s\n", hht.time(), hht.statistics().steps,
                hht.statistics().rejected_steps, msg.c_str());
    EXPECT_NE(msg.find("min_step_fraction"), std::string::npos);
    EXPECT_EQ(hht.statistics().status, IntegratorStatus::kFailed);
    // The last successful steps were about dt / 2^8 = 4e-4 s long, near
    // t = 1 - 4e-4 / 1.4: a few hundred steps at most, not an endless crawl.
    EXPECT_GT(hht.time(), 0.99);
    EXPECT_LT(hht.statistics().steps, 2000);
    EXPECT_EQ(reported, hht.statistics().rejections);
    EXPECT_EQ(static_cast<long>(reported.size()), hht.statistics().rejected_steps);
  }
}

// Modified Newton (reuse_factorization) reaches the same solution as full
// Newton on a nonlinear oscillator trajectory, with fewer factorisations.
TEST(Hht, FactorizationReuseSameSolutionFewerFactorizations) {
  Oscillator osc(1.0, 1.0, 5.0);
  IntegratorOptions full;
  full.dt_s = 0.01;
  full.residual_rtol = 1e-12;
  IntegratorOptions reuse = full;
  reuse.reuse_factorization = true;
  HhtIntegrator a(osc, full), b(osc, reuse);
  a.initialize(0, Eigen::VectorXd::Constant(1, 0.5));
  b.initialize(0, Eigen::VectorXd::Constant(1, 0.5));
  a.advance_to(2.0);
  b.advance_to(2.0);
  std::printf("reuse: factorisations %ld (full Newton %ld), iterations %ld (%ld)\n", b.statistics().factorizations,
              a.statistics().factorizations, b.statistics().newton_iterations, a.statistics().newton_iterations);
  // Both converge each step to rtol 1e-12 of the step's first residual; the
  // trajectories then agree to ~1e-10 after 200 steps.
  EXPECT_NEAR(a.q()(0), b.q()(0), 1e-9);
  EXPECT_LT(b.statistics().factorizations, a.statistics().factorizations / 2);
}

// A tangent is assembled only where Newton goes on from the iterate: every
// tangent evaluation is factorised, none is spent on a step's converged
// iterate (whose increment already passed its test, so it is evaluated
// without the tangent first). Full Newton with and without the line search
// on the cubic oscillator (nonlinear: several iterations per step). Before
// this, tangent evaluations were factorisations + accepted steps.
TEST(Hht, NoTangentIsAssembledAtTheConvergedIterate) {
  for (int halvings : {0, 4}) {
    Oscillator osc(1.0, 1.0, 5.0);
    IntegratorOptions o;
    o.dt_s = 0.05;
    o.residual_rtol = 1e-10;
    o.increment_rtol = 1e-8;
    o.line_search_halvings = halvings;
    HhtIntegrator s(osc, o);
    s.initialize(0, Eigen::VectorXd::Constant(1, 0.8));
    s.advance_to(2.0);
    const IntegratorStatistics& st = s.statistics();
    SCOPED_TRACE("line_search_halvings " + std::to_string(halvings));
    EXPECT_EQ(st.steps, 40);
    EXPECT_GT(st.newton_iterations, 2 * st.steps);  // nonlinear enough to iterate
    EXPECT_EQ(osc.tangent_evaluations_, st.factorizations);
    // Residual-only evaluations: initialize() and one per step (its converged
    // iterate), plus one for each guess that did not converge after all.
    EXPECT_GE(osc.evaluations_ - osc.tangent_evaluations_, 1 + st.steps);
    EXPECT_LE(osc.evaluations_ - osc.tangent_evaluations_, 1 + st.steps + st.steps / 4);
  }
}

// advance_to_steady_state on the linear oscillator u'' + omega^2 u = 0 from
// u = 1 with Omega = omega h = pi and alpha = -0.2 (steady state u = 0). It
// must stop exactly at the first whole step whose change |u_n+1 - u_n| is
// <= tol (reference: the same integration stepped by hand), and the state it
// leaves follows the spectral envelope of the free decay, |u_n| <= 2 |lambda|^n
// (lambda: the principal eigenvalue of the HHT step, principal_eigenvalue
// above; the other eigenvalue's component decays faster, factor 2 for it and
// round-off). A run whose t_max comes first returns false at t_max; a
// tolerance <= 0 throws.
TEST(Hht, AdvanceToSteadyStateStopsAtTheStatedChangePerStep) {
  const double omega = 2 * M_PI, h = 0.5;  // Omega = pi
  Oscillator osc(1.0, omega * omega);
  IntegratorOptions o;
  o.alpha = -0.2;
  o.dt_s = h;
  const double tol = 1e-10;
  HhtIntegrator ref(osc, o);
  ref.initialize(0, Eigen::VectorXd::Ones(1));
  long n_ref = 0;
  for (double change = 1; change > tol; ++n_ref) {
    const double u = ref.q()(0);
    ref.advance_to((n_ref + 1) * h);
    change = std::abs(ref.q()(0) - u);
  }
  HhtIntegrator hht(osc, o);
  hht.initialize(0, Eigen::VectorXd::Ones(1));
  double change = 0;
  ASSERT_TRUE(hht.advance_to_steady_state(tol, 1000.0, &change));
  const double rho = std::abs(principal_eigenvalue(o.alpha, omega * h));
  const long n = hht.statistics().steps;
  std::printf("steady after %ld steps (by hand: %ld; |lambda| %.4f), last change %.3e, |u| = %.3e, envelope %.3e\n",
              n, n_ref, rho, change, std::abs(hht.q()(0)), std::pow(rho, n));
  EXPECT_EQ(n, n_ref);
  EXPECT_LE(change, tol);
  EXPECT_NEAR(hht.time(), n * h, 1e-12);
  EXPECT_EQ(hht.q()(0), ref.q()(0));
  EXPECT_LE(std::abs(hht.q()(0)), 2 * std::pow(rho, static_cast<double>(n)));

  HhtIntegrator short_run(osc, o);
  short_run.initialize(0, Eigen::VectorXd::Ones(1));
  EXPECT_FALSE(short_run.advance_to_steady_state(tol, 3.0));
  EXPECT_NEAR(short_run.time(), 3.0, 1e-12);
  EXPECT_THROW(short_run.advance_to_steady_state(0.0, 10.0), common::InputError);
}

}  // namespace
}  // namespace arthrosim::numerics
