// Throughput of the poroelastic MCA shockwave model on the bundled knee
// (data/models/knee_parametric/medium meshes, FCC lattice, Table-1 tissues,
// pore fluid and filtration on, one pulse of 0.33 mJ/mm^2):
//  - BM_KneeBuild/<d>: building the knee model (tissue classification);
//  - BM_KneeSteps/<d>: 40 time steps (prints automata, bonds, time step,
//    filtration sub-steps, throughput in automaton-steps per second of wall
//    time and per CPU second);
//  - BM_KneeFullRun/<d>: the whole 100 us of simulated time (the pulse, 24 us,
//    plus the p-wave transit through the capsule), i.e. the cost of one EFD;
//  - BM_KneeLateSteps/<d>: 40 steps from 70 % of that run, rounded down to a
//    multiple of 40 (1 mm: steps 800-839; the steps before untimed): the cost of a step once the wave and the pore fluid have spread through
//    the knee (at rest, in the first steps, every pore pressure is 0 and the
//    filtration's no-transfer rule always takes the same side).
// d in micrometres (1500 and 1000). Wall time depends on what else runs on
// the machine: the CPU-time counters are the per-core figures.
//
//   build/bench/shockwave_bench --benchmark_filter=KneeSteps
//   build/bench/shockwave_bench --benchmark_filter=KneeFullRun/1000
//   build/bench/shockwave_bench --benchmark_filter=KneeLateSteps/1000
//   OMP_NUM_THREADS=1 build/bench/shockwave_bench --benchmark_filter=KneeSteps
#include <benchmark/benchmark.h>
#include <omp.h>

#include <chrono>
#include <cmath>
#include <ctime>
#include <map>
#include <memory>

#include "common/mesh_io.h"
#include "pipelines/knee_generator.h"
#include "shockwave/applicator_pulse.h"
#include "shockwave/knee_model.h"
#include "shockwave/simulation.h"

namespace arthrosim::shockwave {
namespace {

KneeMeshes knee_meshes() {
  const std::string dir = std::string(ARTHROSIM_SOURCE_DIR) + "/data/models/knee_parametric/medium/";
  KneeMeshes k;
  k.femur = common::read_stl(dir + "femur_bone.stl");
  k.tibia = common::read_stl(dir + "tibia_bone.stl");
  using pipelines::KneeCartilage;
  for (KneeCartilage c : {KneeCartilage::kFemur, KneeCartilage::kTibiaMedial, KneeCartilage::kTibiaLateral}) {
    CartilageSurface s;
    s.name = pipelines::cartilage_file_stem(c);
    s.bone = c == KneeCartilage::kFemur ? BoneId::kFemur : BoneId::kTibia;
    s.articular = common::read_stl(dir + s.name + ".stl");
    s.thickness = pipelines::read_thickness_csv(dir + s.name + "_thickness.csv", s.articular);
    k.cartilage.push_back(s);
  }
  for (auto w : {pipelines::KneeMeniscus::kMedial, pipelines::KneeMeniscus::kLateral})
    k.menisci.emplace_back(w == pipelines::KneeMeniscus::kMedial ? "medial" : "lateral",
                           common::read_stl(dir + pipelines::meniscus_file_stem(w) + ".stl"));
  return k;
}

const Model& knee(int diameter_um) {
  static std::map<int, std::unique_ptr<Model>> cache;
  auto& m = cache[diameter_um];
  if (!m) {
    KneeModelOptions o;
    o.diameter = diameter_um * 1e-6;
    m = std::make_unique<Model>(build_knee_model(knee_meshes(), o, nullptr));
  }
  return *m;
}

double cpu_seconds() {
  timespec ts;
  clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &ts);
  return ts.tv_sec + 1e-9 * ts.tv_nsec;
}

void counters(benchmark::State& state, const Model& m, const Simulation& sim, std::int64_t steps, double wall,
              double cpu) {
  state.counters["automata"] = m.size();
  state.counters["bonds"] = static_cast<double>(m.bonds());
  state.counters["steps"] = static_cast<double>(steps);
  state.counters["dt_ns"] = sim.time_step() * 1e9;
  state.counters["substeps"] = sim.filtration() ? sim.filtration()->substeps() : 0;
  state.counters["fast_automata"] = sim.filtration() ? static_cast<double>(sim.filtration()->fast_automata()) : 0.0;
  state.counters["threads"] = omp_get_max_threads();
  state.counters["wall_s"] = wall;
  state.counters["throughput"] = m.size() * static_cast<double>(steps) / wall;       // automaton-steps/s
  state.counters["per_cpu_s"] = m.size() * static_cast<double>(steps) / cpu;         // per CPU second
}

void BM_KneeBuild(benchmark::State& state) {
  const KneeMeshes k = knee_meshes();
  KneeModelOptions o;
  o.diameter = state.range(0) * 1e-6;
  int n = 0;
  for (auto _ : state) {
    const Model m = build_knee_model(k, o, nullptr);
    n = m.size();
    benchmark::DoNotOptimize(n);
  }
  state.counters["automata"] = n;
}
BENCHMARK(BM_KneeBuild)->Arg(1500)->Arg(1000)->Unit(benchmark::kSecond)->Iterations(1);

void BM_KneeSteps(benchmark::State& state) {
  const Model& m = knee(static_cast<int>(state.range(0)));
  const PressurePulse pulse(PulseShape{}, 330.0);
  const std::int64_t steps = 40;
  double wall = 0.0, cpu = 0.0;
  std::unique_ptr<Simulation> sim;
  for (auto _ : state) {
    sim = std::make_unique<Simulation>(m, SimulationOptions{}, pulse);
    const auto t0 = std::chrono::steady_clock::now();
    const double c0 = cpu_seconds();
    sim->run(steps);
    wall += std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    cpu += cpu_seconds() - c0;
  }
  counters(state, m, *sim, steps * state.iterations(), wall, cpu);
}
BENCHMARK(BM_KneeSteps)->Arg(1500)->Arg(1000)->Unit(benchmark::kSecond)->Iterations(3);

void BM_KneeFullRun(benchmark::State& state) {
  const Model& m = knee(static_cast<int>(state.range(0)));
  const PressurePulse pulse(PulseShape{}, 330.0);
  const double end_time = 100e-6;
  double wall = 0.0, cpu = 0.0;
  std::int64_t steps = 0;
  std::unique_ptr<Simulation> sim;
  for (auto _ : state) {
    sim = std::make_unique<Simulation>(m, SimulationOptions{}, pulse);
    steps = static_cast<std::int64_t>(std::ceil(end_time / sim->time_step())) + 1;
    const auto t0 = std::chrono::steady_clock::now();
    const double c0 = cpu_seconds();
    sim->run(steps);
    wall += std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    cpu += cpu_seconds() - c0;
  }
  counters(state, m, *sim, steps * state.iterations(), wall, cpu);
}
void BM_KneeLateSteps(benchmark::State& state) {
  const Model& m = knee(static_cast<int>(state.range(0)));
  const PressurePulse pulse(PulseShape{}, 330.0);
  const double end_time = 100e-6;
  const std::int64_t steps = 40;
  std::int64_t skip = 0;
  double wall = 0.0, cpu = 0.0;
  std::unique_ptr<Simulation> sim;
  for (auto _ : state) {
    state.PauseTiming();
    sim = std::make_unique<Simulation>(m, SimulationOptions{}, pulse);
    const std::int64_t full = static_cast<std::int64_t>(std::ceil(end_time / sim->time_step())) + 1;
    skip = full * 7 / 10 / steps * steps;
    sim->run(skip);
    state.ResumeTiming();
    const auto t0 = std::chrono::steady_clock::now();
    const double c0 = cpu_seconds();
    sim->run(steps);
    wall += std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    cpu += cpu_seconds() - c0;
  }
  counters(state, m, *sim, steps * state.iterations(), wall, cpu);
  state.counters["first_step"] = static_cast<double>(skip);
}
BENCHMARK(BM_KneeLateSteps)->Arg(1500)->Arg(1000)->Unit(benchmark::kSecond)->Iterations(1);

BENCHMARK(BM_KneeFullRun)->Arg(1500)->Arg(1000)->Unit(benchmark::kSecond)->Iterations(1);

}  // namespace
}  // namespace arthrosim::shockwave

BENCHMARK_MAIN();
