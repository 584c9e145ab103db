// Tests of musculoskeletal/signal.h: Butterworth low-pass (single pass and
// zero-lag), resampling, finite-difference derivatives.
#include "musculoskeletal/signal.h"

#include <gtest/gtest.h>

#include <Eigen/QR>

#include <cmath>

#include "common/error.h"

namespace arthrosim::musculoskeletal {
namespace {

Eigen::VectorXd sine(int n, double rate, double f, double phase = 0.0) {
  Eigen::VectorXd x(n);
  for (int i = 0; i < n; ++i) x(i) = std::sin(2 * M_PI * f * i / rate + phase);
  return x;
}

// Analytic gain of the designed filter: the pre-warped bilinear transform maps
// the analog cutoff exactly, so |H(fc)| = 1/sqrt(2) to rounding (1e-12).
TEST(Butterworth, SinglePassMinus3dBAtCutoffAnalytic) {
  for (int order : {2, 4, 6}) {
    const auto s = butterworth_lowpass(6.0, 100.0, order);
    EXPECT_NEAR(gain(s, 6.0, 100.0), 1.0 / std::sqrt(2.0), 1e-12) << "order " << order;
    EXPECT_NEAR(gain(s, 0.0, 100.0), 1.0, 1e-12);
    // Butterworth: |H|^2 = 1 / (1 + (tan(pi f/fs)/tan(pi fc/fs))^(2N)) after pre-warping.
    const double f = 15.0;
    const double r = std::tan(M_PI * f / 100.0) / std::tan(M_PI * 6.0 / 100.0);
    EXPECT_NEAR(gain(s, f, 100.0), 1.0 / std::sqrt(1.0 + std::pow(r, 2 * order)), 1e-12);
  }
}

// Measured on a signal: a 6 Hz sinusoid through one forward pass. After the
// start transient (decays within ~0.5 s for a 6 Hz pole pair) the amplitude is
// estimated by least squares on 10 s of samples; the estimate is exact for a
// pure sinusoid, so 1e-6 covers the remaining transient.
TEST(Butterworth, SinglePassMinus3dBOnSinusoid) {
  const double rate = 100.0, fc = 6.0;
  const int n = 2000;
  const auto s = butterworth_lowpass(fc, rate, 2);
  const Eigen::VectorXd y = filter_forward(s, sine(n, rate, fc));
  Eigen::MatrixXd A(n - 1000, 2);
  Eigen::VectorXd b(n - 1000);
  for (int i = 1000; i < n; ++i) {
    A(i - 1000, 0) = std::sin(2 * M_PI * fc * i / rate);
    A(i - 1000, 1) = std::cos(2 * M_PI * fc * i / rate);
    b(i - 1000) = y(i);
  }
  const Eigen::Vector2d c = A.colPivHouseholderQr().solve(b);
  EXPECT_NEAR(c.norm(), 1.0 / std::sqrt(2.0), 1e-6);
  // One pass of a 2nd-order Butterworth lags by 90 degrees at its cutoff.
  EXPECT_NEAR(std::atan2(c(1), c(0)), -M_PI / 2, 1e-6);
}

// filtfilt: no phase shift and gain |H|^2. Interior samples (away from the
// padded ends by 2 s) of a 3 Hz and a 6 Hz sinusoid; the end effects of the
// odd-reflection padding decay within ~1 s, so 1e-6 is ample.
TEST(Butterworth, FiltfiltZeroPhaseAndSquaredGain) {
  const double rate = 100.0;
  const int n = 1000;
  LowPassOptions o;
  for (double f : {3.0, 6.0}) {
    const double phase = 0.3;
    const Eigen::VectorXd x = sine(n, rate, f, phase);
    const Eigen::VectorXd y = filtfilt_lowpass(x, rate, o).col(0);
    const double g = std::pow(gain(butterworth_lowpass(6.0, rate, 2), f, rate), 2);
    if (f == 6.0) { EXPECT_NEAR(g, 0.5, 1e-12); }
    double err = 0;
    for (int i = 200; i < n - 200; ++i) err = std::max(err, std::abs(y(i) - g * x(i)));
    EXPECT_LT(err, 1e-6) << "f = " << f;
  }
}

// Odd reflection + steady-state start: a constant passes unchanged (rounding).
// A straight line of slope 1 /s: inside, the backward pass undoes the forward
// lag exactly; what remains is the start transient of the forward pass (lag x
// slope ~ 0.0375 s x 1 /s for the 6 Hz 2nd-order pass) decayed over the 34
// padding samples by exp(-zeta w_n t) = exp(-0.707 * 2 pi 6 * 0.34) ~ 1.2e-4,
// i.e. ~4.5e-6: bound 1e-5.
TEST(Butterworth, FiltfiltKeepsConstantAndLine) {
  Eigen::MatrixXd x(50, 2);
  for (int i = 0; i < 50; ++i) {
    x(i, 0) = 1.5;
    x(i, 1) = 0.2 + 0.01 * i;
  }
  const Eigen::MatrixXd y = filtfilt_lowpass(x, 100.0, LowPassOptions{});
  EXPECT_LT((y.col(0) - x.col(0)).cwiseAbs().maxCoeff(), 1e-12);
  EXPECT_LT((y.col(1) - x.col(1)).cwiseAbs().maxCoeff(), 1e-5);
}

// Periodic padding: one period (n - 1 = 114 intervals, last row = first + drift)
// of harmonics plus a linear drift. Reference: the same signal tiled over 7
// periods, filtered with odd-reflection padding, middle period taken (3 periods
// = 3.4 s from the ends: end effects < 1e-12). The periodic filter's own start
// transient decays over its 4-cutoff-period pad by exp(-0.707 2 pi 6 0.67) ~ 2e-8
// of a signal of amplitude < 0.5: tolerance 1e-8 (measured 5e-10). Derivatives
// at the ends: that error divided by 2h (first, 5e-7) or h^2 (second, 1e-4):
// tolerances 1e-6 and 1e-3 (measured 3e-9 and 3e-7). The odd-reflection filter
// on the single period errs visibly (> 1e-3) at the ends.
TEST(Butterworth, PeriodicPaddingMatchesTiledSignal) {
  const int n = 115, per = n - 1;
  const double rate = 100.0, h = 1.0 / rate, T = per / rate, drift = 1.4;
  auto f = [&](double t) {
    return 0.3 * std::sin(2 * M_PI * t / T + 0.2) + 0.1 * std::cos(2 * M_PI * 4 * t / T) +
           0.05 * std::sin(2 * M_PI * 7 * t / T) + drift * t / T;
  };
  Eigen::MatrixXd one(n, 1), tiled(7 * per + 1, 1);
  for (int i = 0; i < n; ++i) one(i, 0) = f(i / rate);
  for (int i = 0; i < tiled.rows(); ++i) tiled(i, 0) = f(i / rate);
  LowPassOptions periodic;
  periodic.periodic = true;
  const Eigen::MatrixXd a = filtfilt_lowpass(one, rate, periodic);
  const Eigen::MatrixXd tiled_f = filtfilt_lowpass(tiled, rate, LowPassOptions{});
  const Eigen::MatrixXd ref = tiled_f.block(3 * per, 0, n, 1).array() - 3 * drift;
  EXPECT_LT((a - ref).cwiseAbs().maxCoeff(), 1e-8);
  const Eigen::MatrixXd odd = filtfilt_lowpass(one, rate, LowPassOptions{});
  EXPECT_GT((odd - ref).cwiseAbs().maxCoeff(), 1e-3);
  const Eigen::MatrixXd d1 = first_derivative(a, h, true), d2 = second_derivative(a, h, true);
  const Eigen::MatrixXd t1 = first_derivative(tiled_f, h), t2 = second_derivative(tiled_f, h);
  for (int end : {0, n - 1}) {
    EXPECT_NEAR(d1(end, 0), t1(3 * per + end, 0), 1e-6);
    EXPECT_NEAR(d2(end, 0), t2(3 * per + end, 0), 1e-3);
  }
}

TEST(Butterworth, RejectsBadOptions) {
  EXPECT_THROW(butterworth_lowpass(60.0, 100.0, 2), std::invalid_argument);
  EXPECT_THROW(butterworth_lowpass(6.0, 100.0, 3), std::invalid_argument);
  EXPECT_THROW(filtfilt_lowpass(Eigen::MatrixXd::Zero(3, 1), 100.0, {}, "x"), std::exception);
}

// Linear interpolation reproduces linear data exactly (rounding only) from an
// irregular grid onto a 100 Hz grid.
TEST(Resample, ExactOnLinearData) {
  Eigen::VectorXd t(6);
  t << 0.0, 0.013, 0.05, 0.051, 0.2, 0.31;
  Eigen::MatrixXd v(6, 2);
  for (int i = 0; i < 6; ++i) v.row(i) << 2.0 - 3.0 * t(i), 7.0 * t(i);
  const Eigen::VectorXd g = uniform_grid(0.0, 0.31, 100.0);
  ASSERT_EQ(g.size(), 32);
  EXPECT_NEAR(g(31), 0.31, 1e-12);
  const Eigen::MatrixXd r = resample_linear(t, v, g);
  for (int i = 0; i < g.size(); ++i) {
    EXPECT_NEAR(r(i, 0), 2.0 - 3.0 * g(i), 1e-13);
    EXPECT_NEAR(r(i, 1), 7.0 * g(i), 1e-13);
  }
  Eigen::VectorXd bad = t;
  bad(3) = bad(2);
  EXPECT_THROW(resample_linear(bad, v, g, "x.mot"), common::InputError);
  Eigen::VectorXd outside(1);
  outside << 0.4;
  EXPECT_THROW(resample_linear(t, v, outside, "x.mot"), common::InputError);
}

// Derivatives of sin(2 pi t) on [0, 1]: the maximum error (ends included) must
// fall by 4x per halving of h (order 2). Measured orders asserted in [1.9, 2.1].
TEST(Derivatives, SecondOrderConvergenceOnSinusoid) {
  auto errors = [](int n) {
    const double h = 1.0 / (n - 1);
    Eigen::VectorXd x(n), d1(n), d2(n);
    for (int i = 0; i < n; ++i) {
      const double t = i * h;
      x(i) = std::sin(2 * M_PI * t);
      d1(i) = 2 * M_PI * std::cos(2 * M_PI * t);
      d2(i) = -4 * M_PI * M_PI * std::sin(2 * M_PI * t);
    }
    return std::pair{(first_derivative(x, h).col(0) - d1).cwiseAbs().maxCoeff(),
                     (second_derivative(x, h).col(0) - d2).cwiseAbs().maxCoeff()};
  };
  const auto [a1, a2] = errors(101);
  const auto [b1, b2] = errors(201);
  const double order1 = std::log2(a1 / b1), order2 = std::log2(a2 / b2);
  EXPECT_GT(order1, 1.9);
  EXPECT_LT(order1, 2.1);
  EXPECT_GT(order2, 1.9);
  EXPECT_LT(order2, 2.1);
  // A quadratic is differentiated exactly by every formula used (rounding only).
  Eigen::VectorXd q(10);
  for (int i = 0; i < 10; ++i) q(i) = 1.0 + 2.0 * (0.1 * i) - 3.0 * (0.1 * i) * (0.1 * i);
  const Eigen::VectorXd dq = first_derivative(q, 0.1).col(0);
  const Eigen::VectorXd ddq = second_derivative(q, 0.1).col(0);
  for (int i = 0; i < 10; ++i) {
    EXPECT_NEAR(dq(i), 2.0 - 6.0 * 0.1 * i, 1e-12);
    EXPECT_NEAR(ddq(i), -6.0, 1e-10);
  }
}

}  // namespace
}  // namespace arthrosim::musculoskeletal
