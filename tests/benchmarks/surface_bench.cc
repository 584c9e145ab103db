// Benchmark of the surface stage (issue 5 performance target: steady osmotic
// state in <= 30 s on the 2-core machine): data/scenes/osmotic.yaml on the
// bundled knee's medium model (prepared here with 2 mm edges), through
// run_surface_stage exactly as arthrosim-surface runs it (HDF5 + XDMF output
// included). Variants: the scene as bundled (linear_solver auto: UMFPACK with
// the exact non-symmetric follower-pressure tangent) and linear_solver
// cholmod (CHOLMOD on (K + K^T)/2). Prints wall time, steps, Newton
// iterations, factorizations and time per factorization, max deflection and
// the e1 range.
//
// Anchor resolution (issue 5's "femoral mesh of about 3,600 elements"): the
// coarse knee prepared with prepare.surface_edge_length_mm [femur=4.2] (3 mm
// elsewhere) gives 3,579 femoral shells.
//  - BM_OsmoticAnchorStatic/<solver>: data/scenes/osmotic.yaml as bundled
//    (steady_state: true, the direct static solve) through run_surface_stage;
//    solver 0 = as bundled (linear_solver auto: UMFPACK, exact tangent),
//    1 = linear_solver cholmod.
//  - BM_OsmoticAnchorDynamic/<dt_us>/<solver>/<reuse>/<ramp_ms>/<c>: the same
//    femur and effects (cartilage::build_surface_model with the scenario's
//    list and the scene defaults, which are the seed's values) integrated by
//    HHT (alpha -0.2) from rest until the largest weighted change of the
//    coordinates over one step is below 1e-9 m (as
//    numerics::HhtIntegrator::advance_to_steady_state; 1e-6 of the 1.2 mm deflection);
//    dt in microseconds, solver 0 = UMFPACK (exact tangent) / 1 = CHOLMOD on
//    (K + K^T)/2, reuse 1 = modified Newton (factorisation kept while the
//    residual contracts), the osmotic pressure ramped over ramp_ms (0: full
//    pressure at t = 0), c 0 = the seed's foundation damping 7e6 N s/mm^3,
//    1 = 7e6 N s/m^3 (docs/shell_element.md, section 4, why). The static
//    equilibrium is solved first (untimed) and the end state compared with
//    it. SURFACE_BENCH_EVERY=n prints a progress line every n steps.
// Both print wall and process CPU time, steps, Newton iterations per step,
// factorisations and the time per factorisation.
//
// BM_GaitCycleAnchor (issue 6 performance target: one gait cycle at the anchor
// resolution in <= 10 minutes on the 2-core machine): data/scenes/gait.yaml on
// the coarse knee prepared with the femur at 4.2 mm (3,579 quads, the
// anchor's 3,616; tibiae 561 + 498 at 3 mm), COMAK rerun on that model first
// (untimed); otherwise as BM_GaitCycle.
// BM_GaitCycle: data/scenes/gait.yaml
// as bundled (coarse knee prepared at 3 mm: femoral 5,568 quads, 1.5 x the
// anchor's 3,616; tibial 561 + 498, the anchor's ~1,100). Its prepare and
// COMAK stages run first (untimed) with the commands the scene runner would
// use (pipelines::plan_stages); the surface stage is then run in-process and
// timed. Prints wall time, steps, rejected attempts, Newton iterations per
// step, active contacts per step, the time split (assembly, contact,
// factorisation, solve), the accuracy rule's worst ratio and the femoral
// deflection and strain extremes.
#include <benchmark/benchmark.h>

#include <chrono>
#include <ctime>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <string>

#include "numerics/hht_integrator.h"
#include "cartilage/surface_model.h"
#include "common/metadata.h"
#include "common/scene.h"
#include "common/scene_edit.h"
#include "pipelines/prepare.h"
#include "pipelines/runner.h"
#include "pipelines/stages.h"
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

// data/scenes/osmotic.yaml, with linear_solver set unless it is "auto" (the
// bundled default); the edited scene (paths absolute) goes into the bench folder.
std::string osmotic_scene(const std::string& linear_solver) {
  const std::string bundled = std::string(ARTHROSIM_SOURCE_DIR) + "/data/scenes/osmotic.yaml";
  if (linear_solver == "auto") return bundled;
  const std::string scene = (bench_dir() / ("osmotic_" + linear_solver + ".yaml")).string();
  std::ofstream(scene) << common::edit_scene_text(bundled, pipelines::scene_schema(), {{"surface.scenarios.osmotic.linear_solver", linear_solver}});
  return scene;
}

void run(benchmark::State& state, const std::string& linear_solver) {
  const std::string scene = osmotic_scene(linear_solver);
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

const fs::path& gait_scene() {
  static const fs::path p = fs::path(ARTHROSIM_SOURCE_DIR) / "data/scenes/gait.yaml";
  return p;
}

/// The gait scene's prepared model and stage-1 kinematics, made once with the
/// commands the scene runner would use; comak_wall_s: that stage's wall time.
struct GaitInputs {
  std::string prepared, kinematics;
  double comak_wall_s = 0;
};
/// The coarse knee prepared at the anchor resolution: femur 4.2 mm (3,579
/// quads), the other surfaces 3 mm; written once to the bench folder.
struct AnchorModel {
  PreparedModel model;
  std::string path;
};
const AnchorModel& anchor_model() {
  static const AnchorModel a = [] {
    AnchorModel m;
    PrepareOptions o;
    o.edge_length = 3e-3;
    o.surface_edge_length["femur"] = 4.2e-3;
    m.model =
        prepare_model(find_model_files(std::string(ARTHROSIM_SOURCE_DIR) + "/data/models/knee_parametric/coarse"), o);
    m.path = (bench_dir() / "prepared_coarse_femur4.2.h5").string();
    common::RunMetadata md;
    md.program = "surface_bench";
    write_prepared_model(m.model, o, md, m.path);
    return m;
  }();
  return a;
}

double cpu_seconds() { return static_cast<double>(std::clock()) / CLOCKS_PER_SEC; }

void BM_OsmoticAnchorStatic(benchmark::State& state) {
  const std::string solver = state.range(0) == 1 ? "cholmod" : "auto";
  const std::string scene = osmotic_scene(solver);
  SurfaceStageOptions o;
  o.prepared = anchor_model().path;
  o.scene = scene;
  o.scenario = "osmotic";
  o.out = (bench_dir() / ("surface_osmotic_anchor_" + solver + ".h5")).string();
  o.progress = false;
  o.argv = {"surface_bench"};
  for (auto _ : state) {
    const double c0 = cpu_seconds();
    const SurfaceStageResult r = run_surface_stage(o);
    const double cpu = cpu_seconds() - c0;
    const SurfaceSummary& s = r.surfaces.at(0);
    std::printf(
        "osmotic anchor static (%s): %s %d nodes %d elements: wall %.2f s (process CPU %.2f s), %ld steps, "
        "%ld Newton iterations, %ld factorizations, %.3f s per factorization (assembly %.2f s, factorization "
        "%.2f s, solve %.2f s), max deflection %.4f mm, e1 %.4g .. %.4g\n",
        solver.c_str(), s.name.c_str(), s.nodes, s.elements, r.wall_s, cpu, r.steps, r.newton_iterations,
        r.factorizations, r.factorizations ? r.factorization_s / r.factorizations : 0.0, r.assembly_s,
        r.factorization_s, r.solve_s, s.max_deflection_m * 1e3, s.e1_min, s.e1_max);
    std::fflush(stdout);
    state.counters["wall_s"] = r.wall_s;
    state.counters["cpu_s"] = cpu;
    state.counters["newton_iterations"] = static_cast<double>(r.newton_iterations);
  }
}
BENCHMARK(BM_OsmoticAnchorStatic)->Arg(0)->Arg(1)->Unit(benchmark::kSecond)->Iterations(1);

void BM_OsmoticAnchorDynamic(benchmark::State& state) {
  const double dt = 1e-6 * static_cast<double>(state.range(0));
  const bool cholmod = state.range(1) == 1, reuse = state.range(2) == 1;
  const double ramp = 1e-3 * static_cast<double>(state.range(3));
  const PreparedSurface* femur = nullptr;
  for (const PreparedSurface& s : anchor_model().model.surfaces)
    if (s.name == "femur") femur = &s;
  if (!femur) {
    state.SkipWithError("the prepared anchor model has no femur");
    return;
  }
  cartilage::SurfaceInput in;
  in.name = "femur";
  in.mesh = femur->quads;
  in.mesh.name = "femur";
  in.normals = femur->node_normals;
  in.periphery = femur->periphery_nodes;
  // osmotic.yaml's effects; SurfaceParameters' defaults are the scene
  // defaults (seed values: 1 mm shells, 400 MPa, 0.3, 1000 kg/m^3, k 0.7
  // N/mm^3, c 7e6 N s/mm^3, 0.2 MPa).
  const std::vector<std::string> effects = {"foundation_springs", "foundation_damping", "osmotic_pressure",
                                            "periphery_fixed", "inertia"};
  const cartilage::SurfaceParameters par;
  cartilage::SurfaceParameters par_dyn;
  par_dyn.osmotic_ramp_s = ramp;  // 0: the full pressure from t = 0
  // Foundation damping: 0 = the seed's printed 7e6 N s/mm^3 (c/k = 1e7 s),
  // 1 = 7e6 N s/m^3 (c/k = 0.01 s, docs/shell_element.md section 5).
  const bool plausible_c = state.range(4) == 1;
  if (plausible_c) par_dyn.foundation_damping_N_s_m3 = 7e6;
  auto stat_model = cartilage::build_surface_model(in, par, effects, cartilage::BoneMotion::fixed(), nullptr);
  numerics::IntegratorOptions so;
  so.quasi_static = true;
  so.dt_s = 1.0;
  so.max_newton_iterations = 30;
  so.solver = numerics::LinearSolverChoice::kCholmod;
  numerics::HhtIntegrator stat(*stat_model, so);
  stat.initialize(0, stat_model->reference_state());
  stat.advance_to(1.0);
  const double w_static = cartilage::nodal_deflection(*stat_model, stat.q()).maxCoeff();
  for (auto _ : state) {
    const auto t0 = std::chrono::steady_clock::now();
    const double c0 = cpu_seconds();
    auto model = cartilage::build_surface_model(in, par_dyn, effects, cartilage::BoneMotion::fixed(), nullptr);
    numerics::IntegratorOptions o;  // alpha -0.2 (seed)
    o.dt_s = dt;
    o.reuse_factorization = reuse;
    o.solver = cholmod ? numerics::LinearSolverChoice::kCholmod : numerics::LinearSolverChoice::kUmfpack;
    o.keep_step_log = false;
    numerics::HhtIntegrator hht(*model, o);
    hht.initialize(0, model->reference_state());
    const double tol = 1e-9;
    double change = 0;
    bool steady = false;
    // Steps as numerics::HhtIntegrator::advance_to_steady_state takes them, with a
    // progress line every `every` steps (environment SURFACE_BENCH_EVERY).
    const char* every_env = std::getenv("SURFACE_BENCH_EVERY");
    const long every = every_env ? std::atol(every_env) : 0;
    while (!steady && hht.time() < 4000 * dt * (1 - 1e-12)) {
      steady = hht.advance_to_steady_state(tol, hht.time() + dt, &change);
      const auto& st = hht.statistics();
      if (every > 0 && st.steps % every == 0)
        std::printf("  t = %.4f s: change %.2e m, %ld steps, %ld Newton iterations, %ld factorizations, %ld rejected, "
                    "%s, process CPU %.1f s\n",
                    hht.time(), change, st.steps, st.newton_iterations, st.factorizations, st.rejected_steps,
                    st.linear_solver.c_str(), cpu_seconds() - c0);
      std::fflush(stdout);
    }
    const double wall = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    const double cpu = cpu_seconds() - c0;
    const auto& st = hht.statistics();
    const double w_dyn = cartilage::nodal_deflection(*model, hht.q()).maxCoeff();
    const double diff = (hht.q() - stat.q()).cwiseAbs().cwiseProduct(model->increment_weights()).maxCoeff();
    std::printf(
        "osmotic anchor dynamic (HHT alpha -0.2, dt %g s, pressure ramp %g s, damping c %g N s/m^3, %s, %s): %d "
        "elements: %s after %ld steps (t = %.4f s, "
        "last change %.2e m); wall %.2f s (process CPU %.2f s); %.2f Newton iterations per step; %ld "
        "factorizations, %.3f s each; assembly %.2f s, factorization %.2f s, solve %.2f s; %ld rejected; max "
        "deflection %.6f mm (static %.6f mm), max weighted difference to the static state %.2e m; solver in "
        "use %s (%ld switches)\n",
        dt, ramp, par_dyn.foundation_damping_N_s_m3, cholmod ? "CHOLMOD on (K + K^T)/2" : "UMFPACK", reuse ? "factorisation reuse" : "full Newton",
        model->num_elements(), steady ? "steady" : "NOT steady", st.steps, hht.time(), change, wall, cpu,
        st.steps ? static_cast<double>(st.newton_iterations) / st.steps : 0.0, st.factorizations,
        st.factorizations ? st.factorization_s / st.factorizations : 0.0, st.assembly_s, st.factorization_s,
        st.solve_s, st.rejected_steps, w_dyn * 1e3, w_static * 1e3, diff, st.linear_solver.c_str(),
        st.solver_switches);
    std::fflush(stdout);
    state.counters["wall_s"] = wall;
    state.counters["cpu_s"] = cpu;
    state.counters["steps"] = static_cast<double>(st.steps);
  }
}
BENCHMARK(BM_OsmoticAnchorDynamic)
    ->Args({1000, 1, 1, 10, 1})
    ->Args({100, 1, 1, 10, 1})
    ->Args({1000, 1, 1, 10, 0})
    ->Args({1000, 1, 1, 0, 1})
    ->Args({1000, 1, 0, 10, 1})
    ->Unit(benchmark::kSecond)
    ->Iterations(1);

// Runs the gait scene's prepare and COMAK stages into bench_dir()/tag (once
// per tag), or only COMAK on `prepared` when given (the anchor resolution:
// stage 1 reads the prepared meshes, so it is rerun on them).
GaitInputs make_gait_inputs(const std::string& tag, const std::string& prepared = "") {
  GaitInputs g;
  const fs::path out = bench_dir() / tag;
  fs::create_directories(out);
  for (const StageStep& s : plan_stages(pipelines::load_scene(gait_scene()), out)) {
    if (s.name == "prepare" && !prepared.empty()) {
      g.prepared = prepared;
      continue;
    }
    if (s.name != "prepare" && s.name != "comak") continue;
    std::vector<std::string> args = s.arguments;
    for (std::size_t i = 0; i + 1 < args.size(); ++i)
      if (args[i] == "--prepared" && !prepared.empty()) args[i + 1] = prepared;
    std::string cmd = (fs::path(ARTHROSIM_BINARY_DIR) / "bin" / s.executable).string();
    for (const std::string& a : args) cmd += " '" + a + "'";
    cmd += " --quiet";
    std::printf("setup: %s\n", cmd.c_str());
    const auto t0 = std::chrono::steady_clock::now();
    const int rc = std::system(cmd.c_str());
    const double wall = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    // arthrosim-comak exits 2 when frames failed (marked in the file): the
    // surface stage still imposes the converged ones; report, do not stop.
    if (rc != 0) std::printf("setup: %s exited with status %d\n", s.executable.c_str(), rc);
    if (s.name == "prepare") g.prepared = s.outputs.at(0).string();
    if (s.name == "comak") {
      g.kinematics = s.outputs.at(0).string();
      g.comak_wall_s = wall;
    }
  }
  return g;
}
const GaitInputs& gait_inputs() {
  static const GaitInputs in = make_gait_inputs("gait");
  return in;
}
const GaitInputs& gait_anchor_inputs() {
  static const GaitInputs in = make_gait_inputs("gait_anchor", anchor_model().path);
  return in;
}

void gait_cycle(benchmark::State& state, const GaitInputs& in, const std::string& tag) {
  const fs::path out = bench_dir() / tag;
  SurfaceStageOptions o;
  o.prepared = in.prepared;
  o.kinematics = in.kinematics;
  o.scene = gait_scene().string();
  o.scenario = "gait";
  o.out = (out / "surface_gait_bench.h5").string();
  o.progress = false;
  o.argv = {"surface_bench"};
  for (auto _ : state) {
    const SurfaceStageResult r = run_surface_stage(o);
    std::printf("gait cycle, %s (%s): wall %.1f s, %ld steps, %ld rejected attempts, %.2f Newton iterations per "
                "step, %.0f active contacts per step with contact (%ld of %ld steps), time split: assembly %.1f s "
                "(contact %.1f s), factorisation %.1f s, solve %.1f s; worst penetration/deflection %.3f "
                "(%ld steps over 0.1), max penetration %.3f mm\n",
                tag.c_str(), r.status == SurfaceStageStatus::kCompleted ? "completed" : "FAILED", r.wall_s, r.steps,
                r.rejected_steps, r.steps ? static_cast<double>(r.newton_iterations) / r.steps : 0.0,
                r.contact_steps ? static_cast<double>(r.active_contacts_sum) / r.contact_steps : 0.0, r.contact_steps,
                r.steps, r.assembly_s, r.contact_s, r.factorization_s, r.solve_s, r.worst_penetration_ratio,
                r.penetration_warnings, r.max_penetration_m * 1e3);
    for (const SurfaceSummary& s : r.surfaces)
      std::printf("  %s: %d nodes, %d elements, max deflection %.3f mm at %.2f s, e1 %.4f .. %.4f, e2 min %.4f\n",
                  s.name.c_str(), s.nodes, s.elements, s.max_deflection_m * 1e3, s.max_deflection_time_s, s.e1_min,
                  s.e1_max, s.e2_min);
    state.counters["wall_s"] = r.wall_s;
    state.counters["steps"] = static_cast<double>(r.steps);
  }
}

void BM_GaitCycle(benchmark::State& state) { gait_cycle(state, gait_inputs(), "gait"); }
// Issue 6's target resolution: femoral cartilage at 4.2 mm (3,579 shells).
void BM_GaitCycleAnchor(benchmark::State& state) { gait_cycle(state, gait_anchor_inputs(), "gait_anchor"); }

void BM_OsmoticMediumAuto(benchmark::State& state) { run(state, "auto"); }
void BM_OsmoticMediumCholmod(benchmark::State& state) { run(state, "cholmod"); }
BENCHMARK(BM_OsmoticMediumAuto)->Unit(benchmark::kSecond)->Iterations(1);
BENCHMARK(BM_OsmoticMediumCholmod)->Unit(benchmark::kSecond)->Iterations(1);
BENCHMARK(BM_GaitCycle)->Unit(benchmark::kSecond)->Iterations(1);
BENCHMARK(BM_GaitCycleAnchor)->Unit(benchmark::kSecond)->Iterations(1);

// Only the effects a scene calls for (issue 8). (1) Term level: the first
// 0.15 s of the gait scenario as bundled, and the same with an osmotic
// pressure term built at 0 MPa (a term the scene does not call for: it adds
// no force, only cost). (2) Stage level: the osmotic scene's plan has no
// COMAK stage; the time it would add is that stage's wall time for the gait
// scene's model (the setup above). Prints wall time per step of both runs,
// their ratio and the COMAK time (the effect ledger in each output file,
// /effects, shows osmotic_pressure built only in the second run).
void BM_OnlyRequestedEffects(benchmark::State& state) {
  std::ifstream in(gait_scene());
  const std::string bundled((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  auto variant = [&](bool with_pressure) {
    std::string text = bundled;
    const std::string root = std::string(ARTHROSIM_SOURCE_DIR) + "/data/";
    text.replace(text.find("model: ../"), 10, "model: " + root);
    text.replace(text.find("trial: ../"), 10, "trial: " + root);
    const std::string anchor = "      foundation_from_thickness: true\n";
    std::string extra = "      end_time_s: 0.15\n";
    if (with_pressure) {
      extra += "      osmotic_pressure_mpa: 0\n";
      text.replace(text.find("imposed_kinematics,"), 19, "imposed_kinematics, osmotic_pressure,");
    }
    text.replace(text.find(anchor), anchor.size(), anchor + extra);
    const fs::path p = bench_dir() / (with_pressure ? "gait_short_pressure0.yaml" : "gait_short.yaml");
    std::ofstream(p) << text;
    return p;
  };
  const common::Scene osmotic = pipelines::load_scene(fs::path(ARTHROSIM_SOURCE_DIR) / "data/scenes/osmotic.yaml");
  bool comak_planned = false;
  for (const StageStep& s : plan_stages(osmotic, bench_dir() / "osmotic_plan")) comak_planned |= s.name == "comak";
  for (auto _ : state) {
    double per_step[2] = {0, 0};
    for (int k = 0; k < 2; ++k) {
      SurfaceStageOptions o;
      o.prepared = gait_inputs().prepared;
      o.kinematics = gait_inputs().kinematics;
      o.scene = variant(k == 1).string();
      o.scenario = "gait";
      o.out = (bench_dir() / (k ? "gait_short_pressure0.h5" : "gait_short.h5")).string();
      o.progress = false;
      o.argv = {"surface_bench"};
      const SurfaceStageResult r = run_surface_stage(o);
      per_step[k] = r.steps ? r.wall_s / r.steps : 0;
      std::printf("gait 0-0.15 s %s: %s, wall %.1f s, %ld steps (%.2f s per step), %ld Newton iterations\n",
                  k ? "+ unrequested osmotic_pressure at 0 MPa" : "as bundled",
                  r.status == SurfaceStageStatus::kCompleted ? "completed" : "FAILED", r.wall_s, r.steps,
                  per_step[k], r.newton_iterations);
    }
    std::printf("term level: the unrequested term costs %.1f %% more wall time per step\n",
                100 * (per_step[1] / per_step[0] - 1));
    std::printf("stage level: the osmotic scene plans COMAK: %s; COMAK on the gait scene's model took %.1f s\n",
                comak_planned ? "yes" : "no", gait_inputs().comak_wall_s);
    state.counters["pressure_term_overhead"] = per_step[1] / per_step[0] - 1;
  }
}
BENCHMARK(BM_OnlyRequestedEffects)->Unit(benchmark::kSecond)->Iterations(1);

}  // namespace
}  // namespace arthrosim::pipelines

BENCHMARK_MAIN();
