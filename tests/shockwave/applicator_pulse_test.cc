// Effect applicator_pulse: the pulse shape and its calibration to the energy
// flux density (seed eqs. 1-2).
#include <gtest/gtest.h>

#include <cmath>

#include "common/error.h"
#include "shockwave/applicator_pulse.h"

namespace arthrosim::shockwave {
namespace {

// PII = p^2 T_p / (2 rho c) equals the requested EFD (exactly, by
// construction), T_p is where the shape crosses 90 % of its peak, and the
// shape is continuous with peak 1 and the tail's minimum -f_tail.
TEST(ApplicatorPulse, CalibrationAndShape) {
  const PulseShape s;
  for (double efd : {120.0, 330.0, 800.0}) {
    const PressurePulse p(s, efd, 1.5e6);
    EXPECT_NEAR(p.peak() * p.peak() * p.time_to_90_percent() / (2 * 1.5e6), efd, 1e-9 * efd);
    EXPECT_NEAR(p.normalized(p.time_to_90_percent()), 0.9, 1e-12);
  }
  const PressurePulse p(s, 330.0);
  EXPECT_NEAR(p.peak(), 28.81e6, 0.01e6);  // the figure docs/shockwave.md quotes
  EXPECT_DOUBLE_EQ(p.normalized(-1e-9), 0.0);
  EXPECT_DOUBLE_EQ(p.normalized(2e-6), 1.0);
  double lo = 1.0;
  for (double t = 0; t < p.duration() + 1e-6; t += 1e-9) {
    lo = std::min(lo, p.normalized(t));
    EXPECT_LT(std::abs(p.normalized(t + 1e-9) - p.normalized(t)), 5e-3) << t;  // continuous
  }
  EXPECT_NEAR(lo, -s.tail_fraction, 1e-6);
  EXPECT_DOUBLE_EQ(p.normalized(p.duration() + 1e-9), 0.0);
}

// The reported integral EFD against closed forms: without a tail,
// int s^2 dt = 3/8 t_r + plateau + 3/8 t_f (sin^4 and cos^4 average 3/8); the
// tail adds f^2 T- / 2.
TEST(ApplicatorPulse, IntegralEnergyFluxDensity) {
  PulseShape s;
  const PressurePulse p(s, 330.0, 1.5e6);
  const double plateau = s.positive_duration - s.rise_time - s.fall_time;
  const double pos = p.peak() * p.peak() / 1.5e6 * (0.375 * s.rise_time + plateau + 0.375 * s.fall_time);
  const double tail = p.peak() * p.peak() / 1.5e6 * s.tail_fraction * s.tail_fraction * 0.5 * s.tail_duration;
  // Simpson on 20000 intervals of a C1 integrand: better than 1e-6.
  EXPECT_NEAR(p.efd_positive_integral() / pos, 1.0, 1e-6);
  EXPECT_NEAR(p.efd_total_integral() / (pos + tail), 1.0, 1e-6);
}

TEST(ApplicatorPulse, BadInput) {
  PulseShape s;
  EXPECT_THROW(PressurePulse(s, 0.0), common::InputError);
  EXPECT_THROW(PressurePulse(s, -1.0), common::InputError);
  s.positive_duration = 2e-6;  // shorter than rise + fall
  EXPECT_THROW(PressurePulse(s, 330.0), common::InputError);
  s = PulseShape{};
  s.tail_fraction = 1.5;
  EXPECT_THROW(PressurePulse(s, 330.0), common::InputError);
}

}  // namespace
}  // namespace arthrosim::shockwave
