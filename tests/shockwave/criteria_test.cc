// Regeneration criteria volumes (shockwave/criteria.h) on fields with a known answer.
#include <gtest/gtest.h>

#include "shockwave/criteria.h"
#include "tests/shockwave/test_support.h"

namespace arthrosim::shockwave {
namespace {

// Ten automata of tissue 0 and ten of tissue 1 (SC, d = 1 mm: V = 1 mm^3):
// automaton k of tissue 0 gets P = k * 0.05 MPa, strain k * 0.2 %, pore k *
// 0.3 MPa. Compressive (> 0.15 MPa): k >= 4 (6 automata); distortional in
// [0.05, 1.1] %: k = 1..5 (5); pore in [0.02, 2] MPa: k = 1..6 (6); all: k = 4, 5.
// Tissue 1 (all zero) meets nothing.
TEST(Criteria, VolumesOfPeaksInRange) {
  const Lattice lat = make_lattice(LatticeKind::kSimpleCubic, 1e-3);
  GridSpec g;
  g.count = {20, 1, 1};
  const Model m = build_model(lat, g, {testing::material(1e6, 1e6), testing::material(1e6, 1e6)}, PoreFluid{},
                              [](int i, int, int, const common::Vec3&) { return i < 10 ? 0 : 1; });
  std::vector<double> P(20, 0.0), e(20, 0.0), p(20, 0.0);
  for (int k = 0; k < 10; ++k) {
    P[k] = k * 0.05e6;
    e[k] = k * 0.2e-2;
    p[k] = k * 0.3e6;
  }
  const RegenerationVolumes v = regeneration_volumes(m, 0, P, e, p);
  const double V = 1e-9;
  EXPECT_NEAR(v.tissue, 10 * V, 1e-21);
  EXPECT_NEAR(v.compressive, 6 * V, 1e-21);
  EXPECT_NEAR(v.distortional, 5 * V, 1e-21);
  EXPECT_NEAR(v.pore, 6 * V, 1e-21);
  EXPECT_NEAR(v.all, 2 * V, 1e-21);
  const RegenerationVolumes w = regeneration_volumes(m, 1, P, e, p);
  EXPECT_EQ(w.compressive + w.distortional + w.pore + w.all, 0.0);
  EXPECT_NEAR(w.tissue, 10 * V, 1e-21);
}

}  // namespace
}  // namespace arthrosim::shockwave
