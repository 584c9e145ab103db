// Benchmark of the surface stage (issue 5 performance target: steady osmotic
// state in <= 30 s on the 2-core machine): data/scenes/osmotic.yaml on the
// bundled knee's medium model (prepared here with 2 mm edges), through
// run_surface_stage exactly as arthrosim-surface runs it (HDF5 + XDMF output
// included). Variants: the scene as bundled (linear_solver auto: UMFPACK with
// the exact non-symmetric follower-pressure tangent) and linear_solver
// cholmod (CHOLMOD on (K + K^T)/2). Prints wall time, steps, Newton
// iterations, factorizations and time per factorization, max deflection and
// the e1 range.
#include <benchmark/benchmark.h>

#include <cstdio>
#include <filesystem>
#include <fstream>
#include <string>

#include "common/metadata.h"
#include "pipelines/prepare.h"
#include "pipelines/surface_stage.h"

namespace arthrosim::pipelines {
namespace {

namespace fs = std::filesystem;

const fs::path& bench_dir() {
  static const fs::path d = [] {
    const fs::path p = fs::temp_directory_path() / "arthrosim_surface_bench";
    fs::create_directories(p);
    return p;
  }();
  return d;
}

const std::string& medium_prepared() {
  static const std::string path = [] {
    const std::string p = (bench_dir() / "prepared_medium.h5").string();
    PrepareOptions o;
    o.edge_length = 2e-3;
    const PreparedModel m =
        prepare_model(find_model_files(std::string(ARTHROSIM_SOURCE_DIR) + "/data/models/knee_parametric/medium"), o);
    common::RunMetadata md;
    md.program = "surface_bench";
    write_prepared_model(m, o, md, p);
    return p;
  }();
  return path;
}

void run(benchmark::State& state, const std::string& linear_solver) {
  std::string scene = std::string(ARTHROSIM_SOURCE_DIR) + "/data/scenes/osmotic.yaml";
  if (linear_solver != "auto") {
    // The bundled scene with one more key in the scenario.
    std::ifstream in(scene);
    std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    const std::string anchor = "      steady_state: true\n";
    text.replace(text.find(anchor), anchor.size(), anchor + "      linear_solver: " + linear_solver + "\n");
    text.replace(text.find("model: ../models"), 16, "model: " + std::string(ARTHROSIM_SOURCE_DIR) + "/data/models");
    scene = (bench_dir() / ("osmotic_" + linear_solver + ".yaml")).string();
    std::ofstream(scene) << text;
  }
  SurfaceStageOptions o;
  o.prepared = medium_prepared();
  o.scene = scene;
  o.scenario = "osmotic";
  o.out = (bench_dir() / ("surface_osmotic_" + linear_solver + ".h5")).string();
  o.progress = false;
  o.argv = {"surface_bench"};
  for (auto _ : state) {
    const SurfaceStageResult r = run_surface_stage(o);
    const SurfaceSummary& s = r.surfaces.at(0);
    std::printf(
        "osmotic medium knee (%s): %s %d nodes %d elements: wall %.2f s, %ld steps, %ld Newton iterations, "
        "%ld factorizations, %.3f s per factorization (assembly %.2f s, factorization %.2f s, solve %.2f s), "
        "max deflection %.4g mm, e1 %.4g .. %.4g\n",
        linear_solver.c_str(), s.name.c_str(), s.nodes, s.elements, r.wall_s, r.steps, r.newton_iterations,
        r.factorizations, r.factorizations ? r.factorization_s / r.factorizations : 0.0, r.assembly_s,
        r.factorization_s, r.solve_s, s.max_deflection_m * 1e3, s.e1_min, s.e1_max);
    state.counters["wall_s"] = r.wall_s;
    state.counters["newton_iterations"] = static_cast<double>(r.newton_iterations);
  }
}

void BM_OsmoticMediumAuto(benchmark::State& state) { run(state, "auto"); }
void BM_OsmoticMediumCholmod(benchmark::State& state) { run(state, "cholmod"); }
BENCHMARK(BM_OsmoticMediumAuto)->Unit(benchmark::kSecond)->Iterations(1);
BENCHMARK(BM_OsmoticMediumCholmod)->Unit(benchmark::kSecond)->Iterations(1);

}  // namespace
}  // namespace arthrosim::pipelines

BENCHMARK_MAIN();
