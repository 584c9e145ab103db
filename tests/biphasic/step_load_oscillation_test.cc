// The first step after a step load, the classic failure of equal-order u-p
// elements (Terzaghi's problem: the fluid carries the whole load at 0+ and a
// drained surface drops the pressure to zero within sqrt(c dt),
// c = H_A k).
//
// Set-up as confined_compression_test.cc (column, drained top, confined,
// step load sigma0). The exact first backward-Euler step of the continuous
// problem solves p - c dt p'' = sigma0 with p = 0 at the top and p' = 0 at the
// impermeable bottom:
//   p1(d) = sigma0 (1 - cosh((h - d) / l) / cosh(h / l)),  l = sqrt(c dt),
// d the depth below the drained surface.
#include <gtest/gtest.h>

#include <cstdio>
#include <numeric>

#include "biphasic/trapezoidal.h"
#include "biphasic_fixtures.h"

namespace arthrosim::biphasic {
namespace {

constexpr double kH = 0.7e6, kK = 2e-15, kHeight = 2e-3, kSigma0 = 0.1e6;
constexpr int kLayers = 16;
constexpr double kElement = kHeight / kLayers;
constexpr double kC = kH * kK;  // consolidation coefficient [m^2/s]

// Pressure / sigma0 at the corner nodes above surface vertex 0 after the
// first step of length dt, from the top (index 0) to the bottom.
Eigen::VectorXd first_step_profile(ElementPair pair, double dt) {
  const common::QuadMesh s = testing::grid_surface(1, 1, 1e-3, 1e-3, kHeight);
  LayerSystem sys = assemble_layer(
      extrude_layer(s, testing::constant_normals(4, Eigen::Vector3d::UnitZ()),
                    Eigen::VectorXd::Constant(4, kHeight), kLayers),
      {kH, 0.1, kK}, pair);
  std::vector<int> all(sys.num_u_nodes());
  std::iota(all.begin(), all.end(), 0);
  std::vector<int> fixed_u = testing::dofs_of(all, {0, 1});
  for (int d : testing::dofs_of(sys.mesh.bone_nodes(sys.u_order()), {2})) fixed_u.push_back(d);
  std::sort(fixed_u.begin(), fixed_u.end());
  TrapezoidalIntegrator integ(sys, fixed_u, sys.mesh.articular_nodes(1), {dt, 1.0});
  Eigen::VectorXd t = Eigen::VectorXd::Zero(12);
  for (int v = 0; v < 4; ++v) t[3 * v + 2] = -kSigma0;
  StepInput in;
  in.F_t = sys.surface_load * t;
  integ.step(in);
  Eigen::VectorXd p(kLayers + 1);
  for (int j = 0; j <= kLayers; ++j) p[j] = integ.p()[sys.mesh.q1_node(0, kLayers - j)] / kSigma0;
  return p;
}

double exact_first_step(double depth, double dt) {
  const double l = std::sqrt(kC * dt);
  return 1.0 - std::cosh((kHeight - depth) / l) / std::cosh(kHeight / l);
}

// dt as a multiple of the element diffusion time h_e^2 / c.
double dt_for(double ratio) { return ratio * kElement * kElement / kC; }

TEST(StepLoad, TaylorHoodPressureIsBoundedAndLocal) {
  // Q2-Q1 from far below to above the resolution limit: no checkerboard. The
  // under-resolved drained boundary layer (l << h_e) gives one overshoot
  // whose deviations decay geometrically with depth, by a factor of about
  // -0.268 per element (measured: 1.268, 0.928, 1.019, 0.995, 1.0014 at
  // c dt / h_e^2 = 2.6e-5); it does not grow as dt -> 0. Bounds: overshoot
  // <= 0.27 sigma0 for every dt; from 4 elements below the surface on, within
  // 0.6 % of the exact first step (0.268^4 = 0.5 %; where the layer is nearly
  // resolved, c dt / h_e^2 = 0.01 and 1, the ordinary discretisation error
  // there is 3.4e-3 and 3.1e-3).
  for (double ratio : {1e-8, 1e-6, 1e-4, 1e-2, 0.25, 1.0, 4.0}) {
    const double dt = dt_for(ratio);
    const Eigen::VectorXd p = first_step_profile(ElementPair::kTaylorHood, dt);
    double deep = 0.0;
    for (int j = 4; j <= kLayers; ++j)
      deep = std::max(deep, std::abs(p[j] - exact_first_step(j * kElement, dt)));
    std::printf("Q2-Q1 c dt/h_e^2 = %-6g max p/sigma0 %.4f, max deviation from 4 elements down %.2e\n",
                ratio, p.maxCoeff(), deep);
    EXPECT_LE(p.maxCoeff(), 1.27) << ratio;
    EXPECT_LT(deep, 6e-3) << ratio;
  }
}

TEST(StepLoad, TaylorHoodFirstStepMonotoneOnceTheLayerIsResolved) {
  // For c dt >= h_e^2 / 4 the drained layer spans half an element and the
  // Q2-Q1 profile increases monotonically from the surface (measured; the
  // smallest ratio tried where it holds). This is the resolution condition
  // stated in docs/biphasic.md.
  for (double ratio : {0.25, 1.0, 4.0, 16.0}) {
    const Eigen::VectorXd p = first_step_profile(ElementPair::kTaylorHood, dt_for(ratio));
    for (int j = 1; j <= kLayers; ++j) EXPECT_GE(p[j], p[j - 1] - 1e-12) << ratio << " node " << j;
    EXPECT_LE(p.maxCoeff(), 1.0 + 1e-12);
  }
}

TEST(StepLoad, EqualOrderPairOscillatesThroughTheColumn) {
  // Q1-Q1 on the same problem: a checkerboard through the whole column whose
  // amplitude grows to the full load as dt -> 0 (measured at c dt / h_e^2 =
  // 2.6e-5: 0, 1.99, 0.01, 1.98, 0.02, ...). The failure the stable pair
  // avoids; asserted so the demonstration cannot silently stop demonstrating.
  const double dt = dt_for(1e-6);
  const Eigen::VectorXd th = first_step_profile(ElementPair::kTaylorHood, dt);
  const Eigen::VectorXd eo = first_step_profile(ElementPair::kEqualOrder, dt);
  double amplitude = 0.0;  // mid-column node-to-node jump
  for (int j = kLayers / 2; j < kLayers; ++j) amplitude = std::max(amplitude, std::abs(eo[j + 1] - eo[j]));
  double th_amplitude = 0.0;
  for (int j = kLayers / 2; j < kLayers; ++j)
    th_amplitude = std::max(th_amplitude, std::abs(th[j + 1] - th[j]));
  std::printf("mid-column node-to-node jump / sigma0: Q1-Q1 %.3f, Q2-Q1 %.2e\n", amplitude, th_amplitude);
  EXPECT_GT(amplitude, 1.0);
  EXPECT_LT(th_amplitude, 1e-3);
}

}  // namespace
}  // namespace arthrosim::biphasic
