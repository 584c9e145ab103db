// Unconfined compression of a biphasic disk between frictionless impermeable
// platens (Armstrong, Lai and Mow 1984), against the analytic force history.
//
// The analytic solution (derived in docs/biphasic.md, "Unconfined
// compression"): with the axial strain eps(t) uniform, the radial
// displacement u(r, t) and the planar dilatation e = (1/r) d(r u)/dr obey
// de/dt = H_A k lap(e) for a step in strain, the pressure is
// p = H_A (e - e(a)), and the free-draining, traction-free rim gives the
// non-local condition H_A e(a) - 2 mu int_0^1 e r dr = lambda eps0 (unit
// radius). Laplace transform and residues give the step response
//   F(t)/F_inf = 1 + (1 - 2 nu)/(1 + nu) sum_n (2 - c) exp(-alpha_n^2 tau)
//                                               / (alpha_n^2 - c (2 - c)),
// c = (1 - 2 nu)/(1 - nu) = 2 mu / H_A, tau = H_A k t / a^2, alpha_n the roots
// of c J1(alpha) = alpha J0(alpha), F_inf = E_s eps0 pi a^2. The 0+ limit
// needs sum_n (2 - c)/(alpha_n^2 - c (2 - c)) = 1/2, which gives
// F(0+)/F_inf = 3/(2(1 + nu)); both are checked numerically below, so the
// series is verified before the FE is compared with it.
#include <gtest/gtest.h>

#include <cstdio>

#include "biphasic/trapezoidal.h"
#include "biphasic_fixtures.h"

namespace arthrosim::biphasic {
namespace {

using testing::UnconfinedSeries;

constexpr double kH = 0.7e6, kNu = 0.15, kK = 2e-15;
constexpr double kRadius = 3e-3, kThickness = 1.5e-3, kEps0 = 0.05;
constexpr double kTg = kRadius * kRadius / (kH * kK);  // gel time [s]

TEST(UnconfinedCompression, SeriesRootsAndLimits) {
  const UnconfinedSeries s(kNu, 2000);
  // Roots satisfy c J1 = alpha J0 (relative to the size of either term).
  for (size_t n = 0; n < s.alpha.size(); n += 97) {
    const double x = s.alpha[n];
    const double r = s.c * std::cyl_bessel_j(1.0, x) - x * std::cyl_bessel_j(0.0, x);
    EXPECT_LT(std::abs(r), 1e-9 * x * std::abs(std::cyl_bessel_j(1.0, x)) + 1e-12) << n;
  }
  // They approach the zeros of J0 (spacing pi) and are all found (no gap).
  for (size_t n = 1; n < s.alpha.size(); ++n) {
    EXPECT_GT(s.alpha[n] - s.alpha[n - 1], 2.5);
    EXPECT_LT(s.alpha[n] - s.alpha[n - 1], 3.5);
  }
  // sum of coefficients = 1/2 (tail estimated from the asymptotic spacing;
  // with 2000 roots the tail is 5.8e-5 and its estimate good to ~1e-7).
  double sum = 0.0;
  for (double c : s.coef) sum += c;
  EXPECT_NEAR(sum + s.tail(), 0.5, 1e-6);
  EXPECT_NEAR(s.step(0.0), 3.0 / (2.0 * (1.0 + kNu)), 1e-6);
  EXPECT_NEAR(s.step(50.0), 1.0, 1e-15);
  // A ramp held long relaxes to equilibrium; a fast ramp peaks near the 0+ value.
  EXPECT_NEAR(s.ramp(50.0, 0.01), 1.0, 1e-12);
  EXPECT_NEAR(s.ramp(1e-6, 1e-6), 3.0 / (2.0 * (1.0 + kNu)), 2e-3);
}

struct DiskRun {
  std::vector<double> tau, force_ratio, series_ratio;  // F / F_inf
  double rim_expansion_over_eps0_a = 0.0;              // at the last sample
  double max_error = 0.0;                              // max |FE - series| / F_inf
  IntegratorCounters counters;
};

DiskRun run_disk(int n, double dtau, double tau0, double tau_end, const UnconfinedSeries& series,
                 double omega = 0.5) {
  const common::QuadMesh s = testing::quarter_disk_surface(n, kRadius, kThickness);
  LayerSystem sys = assemble_layer(
      extrude_layer(s, testing::constant_normals(s.num_nodes(), Eigen::Vector3d::UnitZ()),
                    Eigen::VectorXd::Constant(s.num_nodes(), kThickness), 1),
      {kH, kNu, kK});
  const common::Points3& X = sys.u_nodes();
  const double tol = 1e-9 * kRadius;
  // Symmetry planes, bottom platen (u_z = 0), top platen (u_z prescribed).
  std::vector<int> fixed_u, top_z;
  for (int a = 0; a < sys.num_u_nodes(); ++a) {
    if (std::abs(X(a, 0)) < tol) fixed_u.push_back(3 * a + 0);
    if (std::abs(X(a, 1)) < tol) fixed_u.push_back(3 * a + 1);
    if (std::abs(X(a, 2)) < tol) fixed_u.push_back(3 * a + 2);
    if (std::abs(X(a, 2) - kThickness) < tol) {
      fixed_u.push_back(3 * a + 2);
      top_z.push_back(3 * a + 2);
    }
  }
  std::sort(fixed_u.begin(), fixed_u.end());
  // Free-draining rim (r = a); platens and symmetry planes impermeable.
  std::vector<int> rim_p = testing::nodes_where(sys.mesh.q1_nodes, [&](const Eigen::Vector3d& x) {
    return std::abs(x.head<2>().norm() - kRadius) < 1e-9 * kRadius;
  });
  TrapezoidalIntegrator integ(sys, fixed_u, rim_p, {dtau * kTg, omega});
  std::vector<char> is_top(sys.num_u_dofs(), 0);
  for (int d : top_z) is_top[d] = 1;
  // Equilibrium force on the discrete section (the O-grid's rim is a chord
  // polygon, 0.64 % smaller than the disk at n = 4): F_inf = E_s eps0 A_h.
  const double area = 4.0 * articular_node_areas(sys.mesh).sum();
  const double F_inf = -sys.material().youngs_modulus() * kEps0 * area;
  DiskRun r;
  StepInput in;
  in.u_fixed = Eigen::VectorXd::Zero(fixed_u.size());
  const int steps = static_cast<int>(std::lround(tau_end / dtau));
  const int rim_node = testing::nodes_where(X, [&](const Eigen::Vector3d& x) {
    return std::abs(x.x() - kRadius) < tol && std::abs(x.y()) < tol && std::abs(x.z() - kThickness / 2) < tol;
  }).at(0);
  for (int i = 1; i <= steps; ++i) {
    const double tau = i * dtau;
    const double top = -kEps0 * kThickness * std::min(tau, tau0) / tau0;
    for (size_t k = 0; k < fixed_u.size(); ++k) in.u_fixed[k] = is_top[fixed_u[k]] ? top : 0.0;
    integ.step(in);
    const Eigen::VectorXd R = integ.reaction();
    double force = 0.0;
    for (int d : top_z) force += R[d];
    force *= 4.0;  // quarter model
    r.tau.push_back(tau);
    r.force_ratio.push_back(force / F_inf);
    r.series_ratio.push_back(series.ramp(tau, tau0));
    r.max_error = std::max(r.max_error, std::abs(r.force_ratio.back() - r.series_ratio.back()));
  }
  r.rim_expansion_over_eps0_a = integ.u()[3 * rim_node] / (kEps0 * kRadius);
  r.counters = integ.counters();
  return r;
}

TEST(UnconfinedCompression, ForceHistoryAgainstArmstrongLaiMow) {
  const UnconfinedSeries series(kNu);
  // Ramp to eps0 in tau0 = 0.01, hold to tau = 0.6 (the equilibrium is
  // checked separately below), trapezoidal rule, dtau = 1e-3.
  const DiskRun r = run_disk(4, 1e-3, 0.01, 0.6, series);
  double peak = 0.0, peak_series = 0.0;
  for (size_t i = 0; i < r.tau.size(); ++i) {
    peak = std::max(peak, r.force_ratio[i]);
    peak_series = std::max(peak_series, r.series_ratio[i]);
  }
  std::printf("disk n=4: peak F/F_inf FE %.4f series %.4f (F(0+)/F_inf = %.4f); max |error| %.3e F_inf\n",
              peak, peak_series, 3.0 / (2.0 * (1.0 + kNu)), r.max_error);
  for (double t : {0.01, 0.02, 0.05, 0.1, 0.2, 0.4, 0.6}) {
    const size_t i = static_cast<size_t>(std::lround(t / 1e-3)) - 1;
    std::printf("  tau %.2f: FE %.4f series %.4f\n", r.tau[i], r.force_ratio[i], r.series_ratio[i]);
  }
  // Tolerance: the pressure boundary layer at the rim (width sqrt(tau) a) is
  // under-resolved at the end of the fast ramp by the n = 4 O-grid (rim
  // elements 0.125 a wide); the convergence test below shows the error
  // falling at second order. Measured 2.4e-3 F_inf; bound 5e-3.
  EXPECT_LT(r.max_error, 5e-3);
  EXPECT_EQ(r.counters.factorizations, 1);
  EXPECT_EQ(r.counters.solves, static_cast<int>(r.tau.size()));
}

TEST(UnconfinedCompression, ConvergesUnderRefinement) {
  const UnconfinedSeries series(kNu);
  std::vector<double> err;
  for (int n : {2, 4, 8}) err.push_back(run_disk(n, 1e-3, 0.01, 0.1, series).max_error);
  std::printf("disk max |F - series| / F_inf: n=2 %.3e n=4 %.3e n=8 %.3e (rates %.2f %.2f)\n", err[0],
              err[1], err[2], std::log2(err[0] / err[1]), std::log2(err[1] / err[2]));
  EXPECT_LT(err[1], err[0]);
  EXPECT_LT(err[2], err[1]);
  // Measured rates 1.96, 1.99 (second order, as the confined column); bound
  // 1.7 for the finest pair.
  EXPECT_GT(std::log2(err[1] / err[2]), 1.7);
}

TEST(UnconfinedCompression, InstantAndEquilibriumLimits) {
  // A fast ramp (tau0 = 1e-4) approaches the instantaneous (incompressible)
  // response: force 3/(2(1 + nu)) F_inf and rim expansion eps0 a / 2; held to
  // tau = 6 the disk reaches F_inf = E_s eps0 pi a^2 and rim expansion
  // nu eps0 a. Backward Euler after the ramp (large steps, stiff).
  const UnconfinedSeries series(kNu);
  const DiskRun fast = run_disk(8, 2e-5, 1e-4, 1e-4, series);
  std::printf("fast ramp: F/F_inf FE %.4f series %.4f closed form 0+ %.4f; rim u/(eps0 a) %.4f\n",
              fast.force_ratio.back(), fast.series_ratio.back(), 3.0 / (2.0 * (1.0 + kNu)),
              fast.rim_expansion_over_eps0_a);
  // The series at the end of the ramp is within 2e-3 of the 0+ value
  // (SeriesRootsAndLimits). The rim expansion has the same time shape as the
  // force excess: u(a)/(eps0 a) = nu + (1 + nu) (F/F_inf - 1) (both are
  // nu + (1 - 2 nu) sum_n coef_n exp(-alpha_n^2 tau) up to the factor), 0.5
  // at 0+. Measured on the n = 8 O-grid: force 0.30 % below the series,
  // rim expansion 1.0 % below (the rim node sits in the drained layer of
  // width sqrt(1e-4) a = 0.01 a, on 0.0625 a elements); bounds 1 % and 2 %.
  const double ratio0 = 3.0 / (2.0 * (1.0 + kNu));
  const double rim_series = kNu + (1.0 + kNu) * (fast.series_ratio.back() - 1.0);
  EXPECT_NEAR(fast.series_ratio.back(), ratio0, 3e-3);
  EXPECT_NEAR(fast.force_ratio.back(), fast.series_ratio.back(), 0.01 * ratio0);
  EXPECT_NEAR(fast.rim_expansion_over_eps0_a, rim_series, 0.02 * rim_series);
  std::printf("rim expansion at the end of the fast ramp: FE %.4f series %.4f\n",
              fast.rim_expansion_over_eps0_a, rim_series);

  const DiskRun slow = run_disk(4, 0.05, 0.05, 8.0, series, 1.0);
  std::printf("equilibrium: F/F_inf %.6f, rim u/(eps0 a) %.6f (nu = %.2f)\n", slow.force_ratio.back(),
              slow.rim_expansion_over_eps0_a, kNu);
  // At tau = 8 the slowest mode has decayed by exp(-alpha_1^2 8) < 1e-7; the
  // drained elastic state u_r = nu eps0 r is linear, so the elements
  // represent it exactly: round-off-level agreement (1e-6 for the remaining
  // transient and the backward-Euler lag).
  EXPECT_NEAR(slow.force_ratio.back(), 1.0, 1e-6);
  EXPECT_NEAR(slow.rim_expansion_over_eps0_a, kNu, 1e-6);
}

}  // namespace
}  // namespace arthrosim::biphasic
