// Benchmark of the deformable-surface core (issue 5 performance target:
// steady osmotic state in <= 30 s on the 2-core machine).
//
// Model: a 60 x 60 = 3,600-element spherical patch (40 mm x 40 mm projected,
// radius 25 mm; the seed's femoral mesh has 3,616 shells), shells 1 mm thick,
// E = 400 MPa, nu = 0.3, rho = 1000 kg/m^3, compressive foundation springs
// k = 0.7 N/mm^3, osmotic pressure 0.2 MPa on the internal face, boundary
// nodes fixed to the (static) bone (seed 002 values).
//
// Variants:
//   QuasiStatic/UMFPACK  - static equilibrium F(q) = 0 in one load step, full
//                          (non-symmetric) Newton matrix, UMFPACK LU.
//   QuasiStatic/CHOLMOD  - same, CHOLMOD on the symmetric part (K + K^T)/2 of
//                          the Newton matrix (a symmetric approximation of
//                          the follower-pressure tangent: more iterations).
//   HHT/N/reuse/cholmod/r - dynamic, HHT alpha = -0.2, dt = 1e-4 s, from rest
//                          with the pressure applied at t = 0, N steps (or
//                          until the largest weighted nodal change over a step
//                          is < 1e-9 m); prints the last step's change and
//                          the deflection. reuse = 1: modified Newton
//                          (factorisation kept while the residual contracts);
//                          cholmod = 1: CHOLMOD on (K + K^T)/2, else UMFPACK;
//                          residual_rtol = 10^-r.
// Each prints wall time, steps, Newton iterations per step, time per
// factorisation, and the max deflection along the reference normal.
//   ElementInternalForce/K - one element's internal force (K = 0) or force
//                          and consistent tangent (K = 1), on a warped,
//                          stretched and rotated element: the per-element
//                          cost behind every assembly (docs/contact.md,
//                          "Cost of a Newton iteration").
#include <benchmark/benchmark.h>

#include <chrono>
#include <cmath>
#include <ctime>
#include <cstdio>
#include <string>

#include "../cartilage/shell_test_meshes.h"
#include "numerics/hht_integrator.h"
#include "cartilage/shell_model.h"

namespace arthrosim::cartilage {
namespace {

struct OsmoticPatch {
  common::QuadMesh mesh = testing::spherical_patch(60, 0.04, 0.025);
  std::unique_ptr<ShellModel> model;
  explicit OsmoticPatch(bool inertia) {
    mesh.name = "patch";
    const common::Points3 D = quad_mesh_vertex_normals(mesh);
    ShellMaterial mat;  // 400 MPa, 0.3, 1000 kg/m^3
    model = std::make_unique<ShellModel>(mesh, D, Eigen::VectorXd::Constant(mesh.num_nodes(), 1e-3), mat);
    model->add_internal_forces();
    model->add_foundation_springs(7e8);
    model->add_pressure("osmotic_pressure", -1.0, [](double) { return 0.2e6; });
    model->add_periphery_fixed();
    if (inertia) model->add_inertia();
  }
  double max_deflection(const Eigen::VectorXd& q) const {
    double w = 0;
    for (int i = 0; i < model->num_nodes(); ++i)
      w = std::max(w, (q.segment<3>(6 * i) - model->reference_position(i)).dot(model->reference_director(i)));
    return w;
  }
};

// Process CPU time (both threads) [s]: the shared machine's load makes wall
// time noisy, so both are printed.
double cpu_seconds() { return static_cast<double>(std::clock()) / CLOCKS_PER_SEC; }

void report(benchmark::State& state, const char* name, const OsmoticPatch& p, const numerics::HhtIntegrator& s, double wall,
            double cpu) {
  const auto& st = s.statistics();
  const double per_step = st.steps ? static_cast<double>(st.newton_iterations) / st.steps : 0;
  const double t_fact = st.factorizations ? st.factorization_s / st.factorizations : 0;
  std::printf(
      "%s: %d elements, %d dofs; wall %.2f s (process CPU %.2f s); %ld steps (%ld rejected); %.2f Newton iterations/step; "
      "%ld factorisations, %.3f s each (%s, %ld symbolic analyses); assembly %.2f s, factorisation %.2f s, "
      "solve %.2f s; max deflection %.4e m\n",
      name, p.model->num_elements(), p.model->num_dofs(), wall, cpu, st.steps, st.rejected_steps, per_step,
      st.factorizations, t_fact, st.linear_solver.c_str(), st.symbolic_analyses, st.assembly_s, st.factorization_s,
      st.solve_s, p.max_deflection(s.q()));
  state.counters["wall_s"] = wall;
  state.counters["cpu_s"] = cpu;
  state.counters["steps"] = static_cast<double>(st.steps);
  state.counters["newton_per_step"] = per_step;
  state.counters["factorization_s"] = t_fact;
  state.counters["max_deflection_m"] = p.max_deflection(s.q());
}

void BM_OsmoticQuasiStatic(benchmark::State& state) {
  const bool cholmod = state.range(0) == 1;
  for (auto _ : state) {
    const auto t0 = std::chrono::steady_clock::now();
    const double c0 = cpu_seconds();
    OsmoticPatch p(false);
    numerics::IntegratorOptions o;
    o.quasi_static = true;
    o.dt_s = 1.0;
    o.max_newton_iterations = 40;
    o.solver = cholmod ? numerics::LinearSolverChoice::kCholmod : numerics::LinearSolverChoice::kUmfpack;
    numerics::HhtIntegrator s(*p.model, o);
    s.initialize(0, p.model->reference_state());
    s.advance_to(1.0);
    const double wall = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    report(state, cholmod ? "quasi-static CHOLMOD on (K + K^T)/2" : "quasi-static UMFPACK", p, s, wall, cpu_seconds() - c0);
  }
}
BENCHMARK(BM_OsmoticQuasiStatic)->Arg(0)->Arg(1)->Iterations(1)->Unit(benchmark::kSecond);

void BM_OsmoticHht(benchmark::State& state) {
  for (auto _ : state) {
    const auto t0 = std::chrono::steady_clock::now();
    const double c0 = cpu_seconds();
    OsmoticPatch p(true);
    numerics::IntegratorOptions o;  // alpha = -0.2, dt = 1e-4 s (seed)
    o.solver = state.range(2) == 1 ? numerics::LinearSolverChoice::kCholmod : numerics::LinearSolverChoice::kUmfpack;
    o.reuse_factorization = state.range(1) == 1;
    o.residual_rtol = std::pow(10.0, -static_cast<double>(state.range(3)));
    numerics::HhtIntegrator s(*p.model, o);
    s.initialize(0, p.model->reference_state());
    Eigen::VectorXd prev = s.q();
    const Eigen::VectorXd& w = p.model->increment_weights();
    double change = 1;
    int n = 0;
    const int max_steps = static_cast<int>(state.range(0));
    while (change > 1e-9 && n < max_steps) {
      s.advance_to((++n) * o.dt_s);
      change = (s.q() - prev).cwiseAbs().cwiseProduct(w).maxCoeff();
      prev = s.q();
    }
    const double wall = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    std::printf("HHT: after %d steps (t = %.4f s) the max weighted change per step is %.2e m (%s)\n", n, s.time(),
                change, change <= 1e-9 ? "steady" : "not yet steady");
    const std::string name = std::string("HHT alpha=-0.2 dt=1e-4") +
                             (o.reuse_factorization ? ", factorisation reuse" : ", full Newton") +
                             (state.range(2) == 1 ? ", CHOLMOD on (K + K^T)/2" : ", UMFPACK") +
                             ", residual_rtol 1e-" + std::to_string(state.range(3));
    report(state, name.c_str(), p, s, wall, cpu_seconds() - c0);
  }
}
void BM_ElementInternalForce(benchmark::State& state) {
  ShellMaterial m;
  const std::array<Eigen::Vector3d, 4> X = {Eigen::Vector3d(0, 0, 0), Eigen::Vector3d(1.1e-3, 0.1e-3, 0.05e-3),
                                            Eigen::Vector3d(1.3e-3, 0.9e-3, -0.04e-3),
                                            Eigen::Vector3d(-0.1e-3, 1.0e-3, 0.02e-3)};
  std::array<Eigen::Vector3d, 4> D;
  for (auto& d : D) d = Eigen::Vector3d(0.05, -0.03, 1.0).normalized();
  const ShellElement el(X, D, {1e-3, 1.1e-3, 0.9e-3, 1e-3}, m, "bench element");
  // A deterministic deformed state: 2 % stretch, a rotation, a transverse bump.
  Vector24 q = el.reference();
  const Eigen::Matrix3d R = Eigen::AngleAxisd(0.4, Eigen::Vector3d(1, 2, 3).normalized()).toRotationMatrix();
  for (int s = 0; s < 8; ++s) {
    Eigen::Vector3d v = q.segment<3>(3 * s);
    if (s % 2 == 0) v = 1.02 * v + Eigen::Vector3d(0, 0, 1e-5 * s);
    q.segment<3>(3 * s) = R * v;
  }
  const bool want_K = state.range(0) == 1;
  Vector24 f;
  Matrix24 K;
  for (auto _ : state) {
    el.internal_force(q, f, want_K ? &K : nullptr);
    benchmark::DoNotOptimize(f.data());
    benchmark::DoNotOptimize(K.data());
  }
}
BENCHMARK(BM_ElementInternalForce)->Arg(0)->Arg(1)->Unit(benchmark::kMicrosecond);

BENCHMARK(BM_OsmoticHht)
    ->Args({10, 0, 0, 8})
    ->Args({10, 1, 0, 8})
    ->Args({200, 1, 1, 8})
    ->Iterations(1)
    ->Unit(benchmark::kSecond);

}  // namespace
}  // namespace arthrosim::cartilage

BENCHMARK_MAIN();
