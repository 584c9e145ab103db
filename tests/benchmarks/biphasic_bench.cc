// Cost of a biphasic cartilage layer (docs/biphasic.md, "Performance"): one
// layer of about 50k unknowns (Q2-Q1, a 21 x 21-quad curved articular
// surface, 4 element layers, 2 mm thick) under a moving penetration-method
// load for 100 steps. Prints the unknowns, the assembly and factorisation
// times, the time per step and the counters (one factorisation, one solve per
// step).
//
//   build/bench/biphasic_bench --benchmark_repetitions=3 --benchmark_report_aggregates_only=true
//
// GaitCycle runs the whole stage (arthrosim-biphasic with its defaults) on a
// prepared model and a kinematics file named by the environment:
//
//   arthrosim run data/scenes/demo.yaml --out out/demo
//   ARTHROSIM_BIPHASIC_PREPARED=out/demo/prepared.h5 ARTHROSIM_BIPHASIC_KINEMATICS=out/demo/kinematics.h5
//       build/bench/biphasic_bench --benchmark_filter=GaitCycle
//
// and prints per layer the unknowns, factorisation time and time per step,
// and the whole cycle's wall time.
//
// Variants (argument: quads per side of the surface):
//   Assemble/n     - element matrices and surface load operator
//   Factorize/n    - reduction to the free unknowns, scaling, UMFPACK LU
//   Step/n         - one time step (right-hand side, one forward/back
//                    substitution, update); 100 steps per iteration so the
//                    per-step time is time / 100
#include <benchmark/benchmark.h>

#include <cmath>
#include <memory>

#include <cstdlib>
#include <filesystem>
#include <string>

#include "biphasic/layer_problem.h"
#include "common/log.h"
#include "pipelines/biphasic_stage.h"

namespace {

using namespace arthrosim;
using namespace arthrosim::biphasic;

// A spherical cap of radius 40 mm, n x n quads over 30 x 30 mm, normals
// outward, thickness 2 mm: the size of a femoral condyle's cartilage patch.
LayerMesh cap_layer(int n, int layers) {
  const double R = 40e-3, W = 30e-3;
  common::QuadMesh s;
  s.name = "cap";
  s.V.resize((n + 1) * (n + 1), 3);
  common::Points3 normals(s.V.rows(), 3);
  for (int j = 0; j <= n; ++j)
    for (int i = 0; i <= n; ++i) {
      const double x = W * (static_cast<double>(i) / n - 0.5), y = W * (static_cast<double>(j) / n - 0.5);
      const Eigen::Vector3d p(x, y, std::sqrt(R * R - x * x - y * y));
      s.V.row(j * (n + 1) + i) = p.transpose();
      normals.row(j * (n + 1) + i) = p.normalized().transpose();
    }
  s.Q.resize(n * n, 4);
  for (int j = 0; j < n; ++j)
    for (int i = 0; i < n; ++i) {
      const int a = j * (n + 1) + i;
      s.Q.row(j * n + i) << a, a + 1, a + n + 2, a + n + 1;
    }
  return extrude_layer(s, normals, Eigen::VectorXd::Constant(s.V.rows(), 2e-3), layers);
}

const Material kMaterial{0.7e6, 0.1, 2e-15};

// Contact loads of frame k: a paraboloid pressure patch of radius 8 mm whose
// centre moves across the cap, fluid carrying 80 % of it.
SurfaceLoads frame_loads(const LayerMesh& m, int k) {
  const Eigen::Vector3d centre(-6e-3 + 1.2e-3 * k, 0.0, 0.0);
  SurfaceLoads l;
  l.traction = Eigen::VectorXd::Zero(3 * m.num_vertices());
  l.pressure = Eigen::VectorXd::Zero(m.num_vertices());
  for (int v = 0; v < m.num_vertices(); ++v) {
    const double r2 = (m.surface.V.row(v).head<2>().transpose() - centre.head<2>()).squaredNorm();
    const double total = std::max(0.0, 2e6 * (1.0 - r2 / (8e-3 * 8e-3)));
    l.traction.segment<3>(3 * v) = -total * m.normals.row(v).transpose();
    l.pressure[v] = 0.8 * total;
  }
  return l;
}

void report(benchmark::State& state, const LayerProblem& p) {
  const IntegratorCounters& c = p.integrator().counters();
  state.counters["unknowns"] = p.system().num_u_dofs() + p.system().num_p_dofs();
  state.counters["free_unknowns"] = c.free_dofs;
  state.counters["matrix_nnz"] = static_cast<double>(c.matrix_nonzeros);
  state.counters["factorization_s"] = c.factorization_s;
  state.counters["factorizations"] = c.factorizations;
  state.counters["solves"] = c.solves;
  if (c.solves > 0) {
    state.counters["solve_ms_per_step"] = 1e3 * c.solve_s / c.solves;
    state.counters["step_ms"] = 1e3 * c.step_s / c.solves;
    state.counters["max_rel_residual"] = c.max_relative_residual;
  }
}

void Assemble(benchmark::State& state) {
  const LayerMesh m = cap_layer(static_cast<int>(state.range(0)), 4);
  for (auto _ : state) {
    LayerSystem sys = assemble_layer(m, kMaterial);
    benchmark::DoNotOptimize(sys.K.nonZeros());
    state.counters["unknowns"] = sys.num_u_dofs() + sys.num_p_dofs();
  }
}

void Factorize(benchmark::State& state) {
  const LayerSystem sys = assemble_layer(cap_layer(static_cast<int>(state.range(0)), 4), kMaterial);
  std::unique_ptr<LayerProblem> p;
  for (auto _ : state) {
    p = std::make_unique<LayerProblem>(sys, TrapezoidalOptions{0.01, 0.5});
    benchmark::DoNotOptimize(p.get());
  }
  report(state, *p);
}

void Step(benchmark::State& state) {
  const LayerMesh m = cap_layer(static_cast<int>(state.range(0)), 4);
  LayerProblem p(assemble_layer(m, kMaterial), {0.01, 0.5});
  std::vector<double> t;
  std::vector<SurfaceLoads> frames;
  for (int k = 0; k <= 10; ++k) {
    t.push_back(0.1 * k);
    frames.push_back(frame_loads(m, k));
  }
  for (auto _ : state) {
    for (int i = 0; i < 100; ++i) p.step(loads_at(t, frames, p.time() + 0.01));
  }
  report(state, p);
}

void GaitCycle(benchmark::State& state) {
  const char* prepared = std::getenv("ARTHROSIM_BIPHASIC_PREPARED");
  const char* kinematics = std::getenv("ARTHROSIM_BIPHASIC_KINEMATICS");
  if (!prepared || !kinematics) {
    state.SkipWithError(
        "set ARTHROSIM_BIPHASIC_PREPARED and ARTHROSIM_BIPHASIC_KINEMATICS (see the comment at the top of "
        "tests/benchmarks/biphasic_bench.cc)");
    return;
  }
  common::set_log_level(common::LogLevel::kError);
  pipelines::BiphasicStageOptions o;
  o.prepared = prepared;
  o.kinematics = kinematics;
  o.out = (std::filesystem::temp_directory_path() / "arthrosim_biphasic_bench.h5").string();
  o.progress = false;
  pipelines::BiphasicStageResult r;
  for (auto _ : state) r = pipelines::run_biphasic_stage(o);
  state.counters["steps"] = r.steps;
  state.counters["wall_s"] = r.wall_s;
  state.counters["build_s"] = r.build_s;
  state.counters["stepping_s"] = r.stepping_s;
  int total = 0;
  for (const auto& l : r.layers) {
    state.counters[l.name + "_unknowns"] = l.unknowns;
    state.counters[l.name + "_factorization_s"] = l.factorization_s;
    state.counters[l.name + "_step_ms"] = l.solves ? 1e3 * l.step_s / l.solves : 0.0;
    state.counters[l.name + "_solves_per_step"] = r.steps ? static_cast<double>(l.solves) / r.steps : 0.0;
    total += l.unknowns;
  }
  state.counters["unknowns"] = total;
}

BENCHMARK(GaitCycle)->Unit(benchmark::kSecond)->Iterations(1);
BENCHMARK(Assemble)->Arg(21)->Unit(benchmark::kMillisecond)->Iterations(1);
BENCHMARK(Factorize)->Arg(21)->Unit(benchmark::kMillisecond)->Iterations(1);
BENCHMARK(Step)->Arg(21)->Unit(benchmark::kMillisecond)->Iterations(1);

}  // namespace

BENCHMARK_MAIN();
