// Blankevoort 1991 ligament law: closed form, C1 continuity, damping sign,
// hanging block (settles to f = m g; energy conserved without damping).
#include <gtest/gtest.h>

#include <cmath>
#include <functional>

#include "common/error.h"
#include "musculoskeletal/ligament.h"

namespace msk = arthrosim::musculoskeletal;

namespace {
msk::BlankevoortParameters params(double k, double l0, double c) {
  msk::BlankevoortParameters p;
  p.stiffness = k;
  p.slack_length = l0;
  p.damping = c;
  return p;
}
}  // namespace

TEST(Blankevoort, CurveMatchesClosedForm) {
  const auto p = params(820.0, 0.03, 0.0);
  const double et = 0.06;
  for (double e : {-0.2, -1e-9, 0.0, 1e-4, 0.01, 0.03, 0.0599, 0.06, 0.0601, 0.1, 0.3}) {
    const double l = p.slack_length * (1 + e);
    double expected = 0.0;
    if (e > 0 && e < et) expected = 820.0 * e * e / (2 * et);
    if (e >= et) expected = 820.0 * (e - et / 2);
    const auto f = msk::blankevoort_force(p, l, 0.0);
    // Only round-off from l = l0 (1 + e) and back: relative 1e-12.
    EXPECT_NEAR(f.strain, e, 1e-14);
    EXPECT_NEAR(f.total, expected, 1e-12 * (1 + std::abs(expected))) << "e = " << e;
    EXPECT_GE(f.total, 0.0);
  }
}

TEST(Blankevoort, ContinuousValueAndSlopeAtTransitionStrain) {
  const auto p = params(600.0, 0.05, 0.0);
  const double et = p.transition_strain, l0 = p.slack_length;
  const double eps = 1e-7;
  auto f = [&](double e) { return msk::blankevoort_force(p, l0 * (1 + e), 0.0).total; };
  // Value: the gap across e_t is the slope (~k) times the 2 eps step: < 1e-3 N.
  EXPECT_NEAR(f(et - eps), f(et + eps), 600.0 * 2 * eps * 1.01);
  EXPECT_NEAR(f(et), 600.0 * et / 2, 1e-10);
  // One-sided slopes (df/de): both equal k within the O(eps k / e_t) FD error.
  const double left = (f(et - eps) - f(et - 2 * eps)) / eps;
  const double right = (f(et + 2 * eps) - f(et + eps)) / eps;
  EXPECT_NEAR(left, 600.0, 600.0 * 1e-4);
  EXPECT_NEAR(right, 600.0, 600.0 * 1e-4);
  // Analytic dF/dl agrees with both sides.
  EXPECT_NEAR(msk::blankevoort_force(p, l0 * (1 + et), 0).dtotal_dlength * l0, 600.0, 1e-9);
  // At e = 0 the slope is 0 from both sides (C1 there too).
  const double at0 = (f(eps) - f(-eps)) / (2 * eps);
  EXPECT_NEAR(at0, 0.0, 600.0 * eps / et);
}

TEST(Blankevoort, DampingOnlyWhileStretchingAndSmoothedNearZero) {
  const double c = 2.0, l0 = 0.04;
  const auto p = params(500.0, l0, c);
  // Well inside the taut region (e > e_s = 0.01): damping = c de/dt exactly.
  const double l = l0 * 1.05, v = 0.01;  // de/dt = v/l0 = 0.25 /s
  auto stretching = msk::blankevoort_force(p, l, v);
  EXPECT_NEAR(stretching.damping, c * v / l0, 1e-12);
  EXPECT_GT(stretching.total, stretching.elastic);
  // Shortening: no damping at all (never pushes, never pulls extra).
  auto shortening = msk::blankevoort_force(p, l, -v);
  EXPECT_EQ(shortening.damping, 0.0);
  EXPECT_EQ(shortening.total, shortening.elastic);
  // Slack: no force even when stretching fast.
  EXPECT_EQ(msk::blankevoort_force(p, l0 * 0.99, 10 * v).total, 0.0);
  // Smooth switch-on: damping -> 0 continuously as e -> 0+, and increases with e.
  double prev = 0.0;
  for (double e : {1e-6, 1e-4, 0.002, 0.005, 0.008, 0.0099}) {
    const double fd = msk::blankevoort_force(p, l0 * (1 + e), v).damping;
    EXPECT_GT(fd, prev);
    EXPECT_LT(fd, c * v / l0);
    prev = fd;
  }
  EXPECT_LT(msk::blankevoort_force(p, l0 * (1 + 1e-6), v).damping, 1e-6 * c * v / l0);
  // Analytic speed derivative equals c/l0 * s(e) (= c/l0 above e_s).
  EXPECT_NEAR(stretching.dtotal_dspeed, c / l0, 1e-12);
}

TEST(Blankevoort, InvalidParametersAreRejectedWithTheirName) {
  auto p = params(-5.0, 0.03, 0.0);
  try {
    msk::validate(p, "ligament ACLam bundle 2");
    FAIL() << "negative stiffness accepted";
  } catch (const arthrosim::common::InputError& e) {
    EXPECT_NE(std::string(e.what()).find("ACLam bundle 2"), std::string::npos);
    EXPECT_NE(std::string(e.what()).find("stiffness"), std::string::npos);
  }
  p = params(100.0, 0.0, 0.0);
  EXPECT_THROW(msk::validate(p, "x"), arthrosim::common::InputError);
  p = params(100.0, 0.01, -1.0);
  EXPECT_THROW(msk::validate(p, "x"), arthrosim::common::InputError);
}

namespace {
// Block of mass m hanging from a fixed point on one bundle; x = ligament length,
// m x'' = m g - f(x, x'). Classical RK4.
struct Block {
  msk::BlankevoortParameters p;
  double m = 10.0, g = 9.81;
  void rhs(double x, double v, double& dx, double& dv) const {
    dx = v;
    dv = g - msk::blankevoort_force(p, x, v).total / m;
  }
  void step(double& x, double& v, double h) const {
    double k1x, k1v, k2x, k2v, k3x, k3v, k4x, k4v;
    rhs(x, v, k1x, k1v);
    rhs(x + h / 2 * k1x, v + h / 2 * k1v, k2x, k2v);
    rhs(x + h / 2 * k2x, v + h / 2 * k2v, k3x, k3v);
    rhs(x + h * k3x, v + h * k3v, k4x, k4v);
    x += h / 6 * (k1x + 2 * k2x + 2 * k3x + k4x);
    v += h / 6 * (k1v + 2 * k2v + 2 * k3v + k4v);
  }
  // Strain energy l0 * integral_0^e f de.
  double energy(double x) const {
    const double k = p.stiffness, et = p.transition_strain, l0 = p.slack_length;
    const double e = x / l0 - 1;
    if (e <= 0) return 0.0;
    if (e < et) return l0 * k * e * e * e / (6 * et);
    return l0 * (k * et * et / 6 + k * ((e * e - et * et) / 2 - et / 2 * (e - et)));
  }
};
}  // namespace

TEST(Blankevoort, HangingBlockSettlesToWeight) {
  Block b;
  b.p = params(1000.0, 0.05, 5.0);  // strong damping (only in extension) so it settles in ~s
  double x = b.p.slack_length, v = 0.0;
  const double h = 1e-4;
  for (int i = 0; i < 60000; ++i) b.step(x, v, h);
  const double f = msk::blankevoort_force(b.p, x, v).total;
  // Settled: residual oscillation decays by ~exp(-zeta w t) with zeta w ~ 2.5 /s over 6 s,
  // i.e. to ~1e-6 of the initial 100 N amplitude; allow 1e-3 relative.
  EXPECT_NEAR(f, b.m * b.g, 1e-3 * b.m * b.g);
  EXPECT_NEAR(v, 0.0, 1e-4);
  // Closed-form equilibrium strain in the linear region: e = m g / k + e_t / 2.
  EXPECT_NEAR(x / b.p.slack_length - 1, b.m * b.g / 1000.0 + 0.03, 1e-5);
}

TEST(Blankevoort, NoDampingConservesEnergy) {
  Block b;
  b.p = params(1000.0, 0.05, 0.0);
  double x = b.p.slack_length * 0.98, v = 0.0;  // released 2 % slack: free fall first
  auto total = [&](double x, double v) { return 0.5 * b.m * v * v - b.m * b.g * x + b.energy(x); };
  const double E0 = total(x, v);
  double max_drift = 0.0, max_strain = 0.0;
  const double h = 1e-5;
  for (int i = 0; i < 100000; ++i) {
    b.step(x, v, h);
    max_drift = std::max(max_drift, std::abs(total(x, v) - E0));
    max_strain = std::max(max_strain, x / b.p.slack_length - 1);
  }
  EXPECT_GT(max_strain, 0.2);  // the block went through toe and linear region
  // RK4 at h = 1e-5 s (w h ~ 5e-3) with C1 kinks: drift ~1e-9 J against a
  // scale m g l0 ~ 5 J; 1e-6 J is a tight bound that a wrong energy/force pair fails.
  EXPECT_LT(max_drift, 1e-6);
}
