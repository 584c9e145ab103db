// Confined compression of a biphasic column (Mow et al. 1980): creep under a
// step load, Terzaghi's pore pressure at several times, ramp-and-hold stress
// relaxation; convergence in element size and time step with measured rates;
// the factor-once counters.
//
// Set-up: a square column of side w and height h, bone side (z = 0) fixed and
// impermeable, lateral displacements zero everywhere (confinement by a
// frictionless impermeable chamber: the solution is one-dimensional and the
// column's lateral faces carry no flux), top surface free-draining (p = 0).
#include <gtest/gtest.h>

#include <cstdio>
#include <numeric>

#include "biphasic/trapezoidal.h"
#include "biphasic_fixtures.h"

namespace arthrosim::biphasic {
namespace {

using testing::creep_fraction;
using testing::terzaghi_pressure;

// Tibial cartilage-like values (docs/biphasic.md): tau = h^2/(H k) = 2857 s.
constexpr double kH = 0.7e6;     // aggregate modulus [Pa]
constexpr double kNu = 0.1;      // irrelevant in confined compression
constexpr double kK = 2e-15;     // permeability [m^4/(N s)]
constexpr double kHeight = 2e-3; // [m]
constexpr double kWidth = 1e-3;  // [m]
constexpr double kTau = kHeight * kHeight / (kH * kK);

Material material() { return {kH, kNu, kK}; }

struct Column {
  LayerSystem sys;
  std::vector<int> fixed_u, fixed_p;
  std::vector<int> top_z;       // u_z dofs of the top nodes
  int top_vertex0_z = -1;       // u_z dof of the top node above surface vertex 0
  double area = kWidth * kWidth;
};

// `prescribe_top`: the top's axial displacement is prescribed (relaxation)
// instead of loaded (creep).
Column make_column(int layers, bool prescribe_top, ElementPair pair = ElementPair::kTaylorHood) {
  const common::QuadMesh s = testing::grid_surface(1, 1, kWidth, kWidth, kHeight);
  LayerMesh mesh = extrude_layer(s, testing::constant_normals(4, Eigen::Vector3d::UnitZ()),
                                 Eigen::VectorXd::Constant(4, kHeight), layers);
  Column c{assemble_layer(std::move(mesh), material(), pair), {}, {}, {}, -1};
  const LayerSystem& sys = c.sys;
  const int order = sys.u_order();
  std::vector<int> all(sys.num_u_nodes());
  std::iota(all.begin(), all.end(), 0);
  c.fixed_u = testing::dofs_of(all, {0, 1});
  for (int d : testing::dofs_of(sys.mesh.bone_nodes(order), {2})) c.fixed_u.push_back(d);
  c.top_z = testing::dofs_of(sys.mesh.articular_nodes(order), {2});
  if (prescribe_top) c.fixed_u.insert(c.fixed_u.end(), c.top_z.begin(), c.top_z.end());
  std::sort(c.fixed_u.begin(), c.fixed_u.end());
  c.fixed_p = sys.mesh.articular_nodes(1);
  c.top_vertex0_z = 3 * sys.mesh.articular_node(order, 0) + 2;
  return c;
}

// Load vector of a uniform compressive total stress sigma0 on the top.
Eigen::VectorXd top_pressure_load(const LayerSystem& sys, double sigma0) {
  Eigen::VectorXd t = Eigen::VectorXd::Zero(3 * sys.mesh.num_vertices());
  for (int v = 0; v < sys.mesh.num_vertices(); ++v) t[3 * v + 2] = -sigma0;
  return sys.surface_load * t;
}

struct CreepRun {
  std::vector<double> T;          // sample times (T units)
  std::vector<double> u_fraction; // top displacement / equilibrium
  std::vector<Eigen::VectorXd> p_axis;  // pressure / sigma0 at the corner nodes of vertex 0, bone..top
  IntegratorCounters counters;
};

// Creep under a step load sigma0 at t = 0+, sampled at the given T (each a
// multiple of dT).
CreepRun run_creep(int layers, double dT, const std::vector<double>& samples, double omega = 1.0,
                   ElementPair pair = ElementPair::kTaylorHood) {
  Column c = make_column(layers, false, pair);
  const double sigma0 = 0.1e6;
  const double u_eq = sigma0 * kHeight / kH;
  TrapezoidalIntegrator integ(c.sys, c.fixed_u, c.fixed_p, {dT * kTau, omega});
  StepInput in;
  in.F_t = top_pressure_load(c.sys, sigma0);
  CreepRun r;
  r.T = samples;
  size_t next = 0;
  while (next < samples.size()) {
    integ.step(in);
    const double T = integ.time() / kTau;
    if (std::abs(T - samples[next]) < 1e-6 * dT) {
      r.u_fraction.push_back(-integ.u()[c.top_vertex0_z] / u_eq);
      Eigen::VectorXd p(layers + 1);
      for (int L = 0; L <= layers; ++L) p[L] = integ.p()[c.sys.mesh.q1_node(0, L)] / sigma0;
      r.p_axis.push_back(p);
      ++next;
    }
  }
  r.counters = integ.counters();
  return r;
}

// Relaxation under a prescribed top displacement: ramp to eps0 at T0, held.
struct RelaxationRun {
  double max_error_over_peak = 0.0;  // max over samples of |sigma FE - series| / |sigma(t0)|
  double final_stress = 0.0;         // [Pa]
  IntegratorCounters counters;
};

RelaxationRun run_relaxation(int layers, double dT, double T_end, double omega) {
  Column c = make_column(layers, true);
  const double eps0 = 0.1, T0 = 0.1;
  const double V0 = eps0 * kHeight / (T0 * kTau);
  TrapezoidalIntegrator integ(c.sys, c.fixed_u, c.fixed_p, {dT * kTau, omega});
  std::vector<char> is_top(c.sys.num_u_dofs(), 0);
  for (int d : c.top_z) is_top[d] = 1;
  const double peak = -testing::relaxation_stress(T0 * kTau, T0 * kTau, V0, kHeight, kH, kK);
  RelaxationRun r;
  StepInput in;
  in.u_fixed = Eigen::VectorXd::Zero(c.fixed_u.size());
  const int steps = static_cast<int>(std::lround(T_end / dT));
  const int every = std::max(1, static_cast<int>(std::lround(0.01 / dT)));
  for (int i = 1; i <= steps; ++i) {
    const double T = i * dT;
    const double top = -eps0 * kHeight * std::min(T, T0) / T0;
    for (size_t k = 0; k < c.fixed_u.size(); ++k) in.u_fixed[k] = is_top[c.fixed_u[k]] ? top : 0.0;
    integ.step(in);
    if (i % every == 0 || i == steps) {
      const Eigen::VectorXd R = integ.reaction();
      double force = 0.0;
      for (int d : c.top_z) force += R[d];
      const double sigma = force / c.area;
      const double series = testing::relaxation_stress(T * kTau, T0 * kTau, V0, kHeight, kH, kK);
      r.max_error_over_peak = std::max(r.max_error_over_peak, std::abs(sigma - series) / peak);
      r.final_stress = sigma;
    }
  }
  r.counters = integ.counters();
  return r;
}

// Smooth creep load sigma0 sin^2(pi T / (2 T1)) up to T1 = 0.1, then constant;
// returns the top displacement [m] and the pressure at the mid-height node [Pa]
// at T_end.
std::pair<double, double> run_smooth_creep(int layers, double dT, double T_end, double omega) {
  Column c = make_column(layers, false);
  TrapezoidalIntegrator integ(c.sys, c.fixed_u, c.fixed_p, {dT * kTau, omega});
  const Eigen::VectorXd F1 = top_pressure_load(c.sys, 0.1e6);
  StepInput in;
  const int steps = static_cast<int>(std::lround(T_end / dT));
  for (int i = 1; i <= steps; ++i) {
    const double T = i * dT;
    const double s = T < 0.1 ? std::pow(std::sin(testing::kPi * T / 0.2), 2) : 1.0;
    in.F_t = s * F1;
    integ.step(in);
  }
  return {integ.u()[c.top_vertex0_z], integ.p()[c.sys.mesh.q1_node(0, layers / 2)]};
}

double rate(double coarse_error, double fine_error, double ratio = 2.0) {
  return std::log(coarse_error / fine_error) / std::log(ratio);
}

TEST(ConfinedCompression, CreepSeriesMatchesTabulatedValues) {
  // The series computed here against the values of Mow et al. 1980 as quoted
  // in shared/references.md (4 digits, so 5e-5): guards the series the FE
  // tests rely on.
  const double T[] = {0.01, 0.05, 0.1, 0.2, 0.5, 1.0, 2.0};
  const double v[] = {0.1128, 0.2523, 0.3568, 0.5041, 0.7640, 0.9313, 0.9942};
  for (int i = 0; i < 7; ++i) EXPECT_NEAR(creep_fraction(T[i]), v[i], 5e-5) << "T = " << T[i];
  // Terzaghi: no pressure at the drained surface, the applied stress at the
  // impermeable bottom before drainage reaches it; its depth average is the
  // creep series' complement (both from the same modes).
  EXPECT_NEAR(terzaghi_pressure(0.0, 0.1), 0.0, 1e-15);
  EXPECT_NEAR(terzaghi_pressure(1.0, 1e-3), 1.0, 1e-12);
  double avg = 0.0;
  const int n = 2000;
  for (int i = 0; i < n; ++i) avg += terzaghi_pressure((i + 0.5) / n, 0.2) / n;
  EXPECT_NEAR(avg, 1.0 - creep_fraction(0.2), 1e-6);  // midpoint rule error ~ 1/n^2
}

TEST(ConfinedCompression, RelaxationSeriesLimits) {
  // Guards the ramp-and-hold series: (a) at equilibrium the stress is H eps0;
  // (b) during a long ramp it reaches the steady constant-rate state
  // -H V0 t / h - V0 h / (3 k) (fluid drag of the steady parabolic pressure,
  // derived in docs/biphasic.md); (c) it is continuous at t0. Relative 1e-9:
  // the exponential sums are converged to 1e-18.
  const double t0 = 0.1 * kTau, V0 = 0.1 * kHeight / t0;
  const double eq = testing::relaxation_stress(50 * kTau, t0, V0, kHeight, kH, kK);
  EXPECT_NEAR(eq, -kH * 0.1, 1e-9 * kH * 0.1);
  const double t_long = 5 * kTau, V_slow = 1e-3 * kHeight / kTau;
  const double steady = -kH * V_slow * t_long / kHeight - V_slow * kHeight / (3 * kK);
  const double s = testing::relaxation_stress(t_long, 10 * kTau, V_slow, kHeight, kH, kK);
  EXPECT_NEAR(s, steady, 1e-9 * std::abs(steady));
  EXPECT_NEAR(testing::relaxation_stress(t0 * (1 - 1e-12), t0, V0, kHeight, kH, kK),
              testing::relaxation_stress(t0 * (1 + 1e-12), t0, V0, kHeight, kH, kK), 1e-6 * kH);
}

TEST(ConfinedCompression, CreepAndTerzaghiPressureAgainstSeries) {
  // 16 element layers, dT = 1e-4 (dt = 0.29 s), backward Euler (omega = 1:
  // the step load is the stiff case, docs/biphasic.md).
  const std::vector<double> samples = {0.01, 0.05, 0.1, 0.2, 0.5, 1.0};
  const CreepRun r = run_creep(16, 1e-4, samples);
  for (size_t i = 0; i < samples.size(); ++i) {
    const double du = std::abs(r.u_fraction[i] - creep_fraction(samples[i]));
    double dp = 0.0;
    for (int L = 0; L <= 16; ++L) {
      const double zeta = 1.0 - L / 16.0;  // distance from the drained top / h
      dp = std::max(dp, std::abs(r.p_axis[i][L] - terzaghi_pressure(zeta, samples[i])));
    }
    std::printf("T = %-5g u/u_eq FE %.6f series %.6f | max |p FE - p series| / sigma0 = %.2e\n",
                samples[i], r.u_fraction[i], creep_fraction(samples[i]), dp);
    // Tolerances: the errors are the sum of the spatial error (second order,
    // ConvergenceInElementSize) and backward Euler's first-order error, both
    // largest at early times when the drained boundary layer sqrt(T) h is
    // thinnest (at T = 0.01 it spans 1.6 elements). Measured: u 7.9e-4 at
    // T = 0.01, 3.5e-4 at 0.05 falling to 1.2e-4; p 5.0e-3 at T = 0.01 then
    // <= 1.0e-3; the bounds are about twice that.
    EXPECT_LT(du, samples[i] < 0.02 ? 1.5e-3 : 7e-4) << "T = " << samples[i];
    EXPECT_LT(dp, samples[i] < 0.02 ? 1.5e-2 : 2.5e-3) << "T = " << samples[i];
  }
  // Factor once, one solve per step.
  EXPECT_EQ(r.counters.factorizations, 1);
  EXPECT_EQ(r.counters.solves, 10000);
  // The scaled system is well conditioned enough for UMFPACK without
  // refinement: residuals at round-off level.
  EXPECT_LT(r.counters.max_relative_residual, 1e-10);
}

TEST(ConfinedCompression, RampAndHoldRelaxationAgainstSeries) {
  // Ramp to eps0 = 0.1 at T0 = 0.1, held to T = 0.3; 16 layers, trapezoidal
  // (omega = 1/2) with dT = 2.5e-4. Measured max error 2.6e-3 of the peak
  // stress (spatial: the rate test below gives 1.1e-2 at 8 layers, 2.6e-3 at
  // 16); bound 5e-3.
  const RelaxationRun r = run_relaxation(16, 2.5e-4, 0.3, 0.5);
  std::printf("relaxation: max |sigma FE - series| / peak = %.3e\n", r.max_error_over_peak);
  EXPECT_LT(r.max_error_over_peak, 5e-3);
  EXPECT_EQ(r.counters.factorizations, 1);
  EXPECT_EQ(r.counters.solves, 1200);
}

TEST(ConfinedCompression, ConvergenceInElementSize) {
  // Relaxation error against the series for 2, 4, 8, 16 element layers at a
  // time step whose error is negligible (trapezoidal, second order in dt,
  // dT = 2.5e-4: below 1e-6 of the peak, ConvergenceInTimeStep). Expected:
  // second order (trilinear pressure). Measured 0.142, 0.0513, 0.0109, 0.0026:
  // rates 1.47, 2.23, 2.07 (the coarsest mesh is pre-asymptotic).
  std::vector<double> err;
  for (int N : {2, 4, 8, 16}) err.push_back(run_relaxation(N, 2.5e-4, 0.3, 0.5).max_error_over_peak);
  const double r1 = rate(err[1], err[2]), r2 = rate(err[2], err[3]);
  std::printf("element size: errors %.3e %.3e %.3e %.3e, rates %.2f %.2f %.2f\n", err[0], err[1],
              err[2], err[3], rate(err[0], err[1]), r1, r2);
  EXPECT_GT(r1, 1.8);
  EXPECT_GT(r2, 1.8);
  EXPECT_LT(r2, 2.4);
}

TEST(ConfinedCompression, ConvergenceInTimeStep) {
  // Smooth creep load on 8 layers; errors against a run with dT / 16 on the
  // same mesh (isolates the time error). Expected rates: 1 for omega = 1
  // (backward Euler), 2 for omega = 1/2 (trapezoidal). Measured (u at T =
  // 0.2): omega 1: 1.00, omega 1/2: 2.00; bounds +-0.15.
  for (double omega : {1.0, 0.5}) {
    const auto ref = run_smooth_creep(8, 2.5e-4 / 16, 0.2, omega);
    std::vector<double> eu, ep;
    for (double dT : {1e-3, 5e-4, 2.5e-4}) {
      const auto r = run_smooth_creep(8, dT, 0.2, omega);
      eu.push_back(std::abs(r.first - ref.first));
      ep.push_back(std::abs(r.second - ref.second));
    }
    const double expected = omega == 1.0 ? 1.0 : 2.0;
    std::printf("omega %.2f: u errors %.3e %.3e %.3e (rates %.3f %.3f), p rates %.3f %.3f\n",
                omega, eu[0], eu[1], eu[2], rate(eu[0], eu[1]), rate(eu[1], eu[2]),
                rate(ep[0], ep[1]), rate(ep[1], ep[2]));
    EXPECT_NEAR(rate(eu[1], eu[2]), expected, 0.15) << "omega " << omega;
    EXPECT_NEAR(rate(ep[1], ep[2]), expected, 0.15) << "omega " << omega;
  }
}

}  // namespace
}  // namespace arthrosim::biphasic
