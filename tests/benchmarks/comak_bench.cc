// Benchmark of the COMAK stage (issue 4 performance target: <= 1 s per frame
// at the fine resolution on the 2-core machine): the whole bundled SYNTHETIC
// trial (115 frames) on the bundled coarse (knee_coarse.urdf) and medium
// (knee.urdf) models with the default options. Prints, per model: frames,
// converged/failed, seconds per frame (wall and process CPU: the machine is
// shared, so wall time includes waiting), Ipopt iterations per frame (mean,
// median, max), and the tibiofemoral contact-force checks of issue 4 (first
// and second stance peaks in body weights, medial/lateral at the first peak).
//
// The *Ankle variants add the ankle equilibrium row with the uniarticular
// ankle stand-ins (ComakOptions::ankle_equilibrium, ankle_muscles.h) and
// also print the mean activations of the quadriceps, gastrocnemii, soleus
// and tibialis anterior per phase of the cycle.
//
// The *Inertia variants switch on the body inertia (ComakOptions::
// body_inertia: the tibia's and patella's own weight and d'Alembert forces
// from the URDF inertials, the shank's terms out of the external load);
// *InertiaShank also gives the tibia link the inverse dynamics' shank
// centre of mass and inertia (the bundled URDF has the mass at the knee
// centre and zero inertia), so its difference to the plain run is the
// patella and the tibia's displacement by the secondary coordinates.
//
// Optional: ARTHROSIM_COMAK_BENCH_STRIDE=k uses every k-th frame;
// ARTHROSIM_COMAK_BENCH_DENSE_JACOBIAN=1 re-evaluates every force term in
// every finite-difference column of dQ/dq (ForceOptions::
// jacobian_skip_unmoved_terms = false; the behaviour before 2026-12-02) to
// compare timings; ARTHROSIM_COMAK_BENCH_NO_MOVE_LIMITS=1 solves attempt 1
// and the second start without step control (ComakOptions::
// move_limits_first = false; the behaviour before 2026-12-03);
// ARTHROSIM_COMAK_BENCH_SINGLE_START=1 solves each frame from the previous
// frame's solution only (ComakOptions::second_start = false, as
// arthrosim-comak --single-start; the behaviour of the third session).
#include <benchmark/benchmark.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <ctime>
#include <map>
#include <string>
#include <vector>

#include "musculoskeletal/ankle_muscles.h"
#include "musculoskeletal/comak.h"
#include "musculoskeletal/gait_trial.h"
#include "musculoskeletal/kinematics_file.h"
#include "musculoskeletal/knee_loads.h"
#include "musculoskeletal/model_io.h"
#include "pipelines/knee_generator.h"

namespace msk = arthrosim::musculoskeletal;
namespace pl = arthrosim::pipelines;

namespace {

enum class Inertia { kOff, kUrdf, kShank };

void run_trial(benchmark::State& state, const char* model_file, bool ankle, bool fine = false,
               Inertia inertia = Inertia::kOff) {
  const std::string root = ARTHROSIM_SOURCE_DIR;
  msk::Model model = msk::load_model(root + "/data/models/knee_parametric/" + model_file);
  if (fine) {
    // The fine resolution of issue 3 (femoral ~29k, tibial ~8.6k cartilage
    // triangles), generated here and put in place of the model's cartilage.
    const auto g = pl::ParametricKnee().generate(pl::fine_knee_options());
    std::map<std::string, msk::SurfaceMesh> by_file;
    for (const auto& p : g.cartilage)
      by_file[pl::cartilage_file_stem(p.which) + ".stl"] = {p.mesh, p.thickness};
    for (const auto& line : msk::use_contact_meshes(model, by_file, "fine generated knee").lines)
      std::printf("  %s\n", line.c_str());
  }
  msk::ComakOptions options;
  if (ankle) {
    msk::add_ankle_muscles(model);
    options.ankle_equilibrium = true;
  }
  if (const char* s = std::getenv("ARTHROSIM_COMAK_BENCH_DENSE_JACOBIAN"); s && std::atoi(s)) {
    options.forces.jacobian_skip_unmoved_terms = false;
    std::printf("  dense finite-difference Jacobian (every term in every column)\n");
  }
  if (const char* s = std::getenv("ARTHROSIM_COMAK_BENCH_NO_MOVE_LIMITS"); s && std::atoi(s)) {
    options.move_limits_first = false;  // as arthrosim-comak --no-move-limits
    std::printf("  attempt 1 and the second start without moving limits\n");
  }
  if (const char* s = std::getenv("ARTHROSIM_COMAK_BENCH_SINGLE_START"); s && std::atoi(s)) {
    options.second_start = false;  // as arthrosim-comak --single-start
    std::printf("  one start per frame (no second start from the passive settle)\n");
  }
  const auto trial = msk::load_gait_trial(root + "/data/trials/synthetic_gait");
  const msk::LegModel leg = msk::leg_model_for_trial(trial);
  const auto loads = msk::compute_knee_loads(trial, leg);
  int stride = 1;
  if (const char* s = std::getenv("ARTHROSIM_COMAK_BENCH_STRIDE")) stride = std::max(1, std::atoi(s));
  const auto frames = msk::comak_frame_inputs(loads, 0, -1, stride, &leg);
  if (inertia != Inertia::kOff) options.body_inertia = true;
  if (inertia == Inertia::kShank) {
    msk::Body& tibia = model.tree.bodies[model.tree.body_index("tibia")];
    tibia.mass = leg.shank.mass_kg;
    tibia.com = leg.shank.p_com;
    tibia.inertia = leg.shank.inertia_about_com();
  }
  msk::ComakProblem problem(model, options);
  const int nm = static_cast<int>(model.muscles.size());
  const double bw = trial.body_mass_kg * 9.80665;
  for (auto _ : state) {
    std::vector<int> iters;
    std::vector<double> t, tf, med, lat;
    std::vector<Eigen::VectorXd> act;
    std::vector<double> knee_cost, ankle_moment;
    const std::clock_t c0 = std::clock();
    const auto sum = msk::run_comak(problem, frames, [&](const auto& f, const auto& r, const auto& d) {
      iters.push_back(r.iterations);
      const auto c = msk::tibiofemoral_contact(model, d);
      t.push_back(f.time);
      act.push_back(r.activations);
      // Objective share of the model file's own (knee-crossing) muscles.
      double fk = 0;
      for (int k = 0; k < nm; ++k)
        if (model.muscles[k].name != "soleus" && model.muscles[k].name != "tibant")
          fk += problem.volume_weights()[k] * r.activations[k] * r.activations[k];
      knee_cost.push_back(fk);
      ankle_moment.push_back(problem.external_ankle_moment(f));
      tf.push_back(c.force.norm() / bw);
      med.push_back(c.medial_force.norm() / bw);
      lat.push_back(c.lateral_force.norm() / bw);
    });
    const double cpu = double(std::clock() - c0) / CLOCKS_PER_SEC;
    std::vector<int> sorted = iters;
    std::sort(sorted.begin(), sorted.end());
    double mean_it = 0;
    for (int i : iters) mean_it += i;
    mean_it /= iters.size();
    // Stance ends at toe-off, 0.684 s (docs/trials.md); first peak before 0.35 s.
    int i1 = -1, i2 = -1;
    for (size_t i = 0; i < t.size(); ++i) {
      if (t[i] < 0.35 && (i1 < 0 || tf[i] > tf[i1])) i1 = static_cast<int>(i);
      if (t[i] >= 0.35 && t[i] < 0.684 && (i2 < 0 || tf[i] > tf[i2])) i2 = static_cast<int>(i);
    }
    std::printf("%s: %d frames, %d converged, %d failed; wall %.3f s/frame, CPU %.3f s/frame; "
                "Ipopt iterations/frame mean %.1f median %d max %d\n",
                model_file, sum.frames, sum.converged, sum.failed, sum.wall_time / sum.frames,
                cpu / sum.frames, mean_it, sorted[sorted.size() / 2], sorted.back());
    if (i1 >= 0 && i2 >= 0)
      std::printf("  tibiofemoral |F|: first peak %.2f BW at %.2f s (medial %.2f, lateral %.2f BW), "
                  "second peak %.2f BW at %.2f s; knee-muscle cost sum V a^2 at the first peak %.4g m^3\n",
                  tf[i1], t[i1], med[i1], lat[i1], tf[i2], t[i2], knee_cost[i1]);
    // Mean activation of muscle groups per phase (docs/comak.md): early
    // stance 0-0.2 s, mid stance 0.2-0.45 s, late stance 0.45-0.684 s
    // (toe-off), swing after.
    auto group = [&](const std::vector<const char*>& names, double t0, double t1) {
      double sum_a = 0, max_a = 0;
      int n = 0;
      for (size_t i = 0; i < t.size(); ++i) {
        if (t[i] < t0 || t[i] >= t1) continue;
        double a = 0;
        int k = 0;
        for (const char* name : names) {
          const int m = model.muscle_index(name);
          if (m >= 0 && m < nm) a += act[i][m], ++k;
        }
        if (!k) return std::pair{-1.0, -1.0};
        a /= k;
        sum_a += a, max_a = std::max(max_a, a), ++n;
      }
      return std::pair{n ? sum_a / n : 0.0, max_a};
    };
    const std::vector<std::pair<const char*, std::vector<const char*>>> groups = {
        {"quadriceps", {"recfem", "vasmed", "vaslat", "vasint"}},
        {"hamstrings", {"bflh", "bfsh", "semimem", "semiten"}},
        {"gastrocnemii", {"gasmed", "gaslat"}},
        {"soleus", {"soleus"}},
        {"tibialis anterior", {"tibant"}}};
    const double phases[5] = {0.0, 0.2, 0.45, 0.684, 10.0};
    std::printf("  activation mean/max: early stance 0-0.2 s | mid 0.2-0.45 s | late 0.45-0.684 s | swing\n");
    for (const auto& [label, names] : groups) {
      if (group(names, 0, 10).first < 0) continue;
      std::printf("    %-18s", label);
      for (int p = 0; p < 4; ++p) {
        const auto [mean_a, max_a] = group(names, phases[p], phases[p + 1]);
        std::printf(" %.3f/%.3f%s", mean_a, max_a, p < 3 ? " |" : "\n");
      }
    }
    if (ankle) {
      const auto lo = std::min_element(ankle_moment.begin(), ankle_moment.end()) - ankle_moment.begin();
      const auto hi = std::max_element(ankle_moment.begin(), ankle_moment.end()) - ankle_moment.begin();
      std::printf("  external moment on the foot about the ankle axis (dorsiflexing +): min %.1f N m at "
                  "%.2f s, max %.1f N m at %.2f s\n",
                  ankle_moment[lo], t[lo], ankle_moment[hi], t[hi]);
    }
    for (int f : sum.failed_frames) std::printf("  failed frame %d\n", f);
    state.counters["s_per_frame"] = sum.wall_time / sum.frames;
    state.counters["cpu_s_per_frame"] = cpu / sum.frames;
    state.counters["iterations_per_frame"] = mean_it;
    state.counters["failed"] = sum.failed;
  }
}

void BM_ComakTrialCoarse(benchmark::State& s) { run_trial(s, "knee_coarse.urdf", false); }
void BM_ComakTrialMedium(benchmark::State& s) { run_trial(s, "knee.urdf", false); }
void BM_ComakTrialCoarseAnkle(benchmark::State& s) { run_trial(s, "knee_coarse.urdf", true); }
void BM_ComakTrialMediumAnkle(benchmark::State& s) { run_trial(s, "knee.urdf", true); }
// Fine: the medium model's URDF (ligaments, muscles, frames) with the fine
// generated cartilage (use_contact_meshes); the knee generation (~35 s) is
// not timed.
void BM_ComakTrialFine(benchmark::State& s) { run_trial(s, "knee.urdf", false, true); }
void BM_ComakTrialCoarseInertia(benchmark::State& s) {
  run_trial(s, "knee_coarse.urdf", false, false, Inertia::kUrdf);
}
void BM_ComakTrialMediumInertia(benchmark::State& s) {
  run_trial(s, "knee.urdf", false, false, Inertia::kUrdf);
}
void BM_ComakTrialCoarseInertiaShank(benchmark::State& s) {
  run_trial(s, "knee_coarse.urdf", false, false, Inertia::kShank);
}
void BM_ComakTrialMediumInertiaShank(benchmark::State& s) {
  run_trial(s, "knee.urdf", false, false, Inertia::kShank);
}
BENCHMARK(BM_ComakTrialCoarse)->Iterations(1)->Unit(benchmark::kSecond);
BENCHMARK(BM_ComakTrialMedium)->Iterations(1)->Unit(benchmark::kSecond);
BENCHMARK(BM_ComakTrialCoarseAnkle)->Iterations(1)->Unit(benchmark::kSecond);
BENCHMARK(BM_ComakTrialMediumAnkle)->Iterations(1)->Unit(benchmark::kSecond);
BENCHMARK(BM_ComakTrialFine)->Iterations(1)->Unit(benchmark::kSecond);
BENCHMARK(BM_ComakTrialCoarseInertia)->Iterations(1)->Unit(benchmark::kSecond);
BENCHMARK(BM_ComakTrialMediumInertia)->Iterations(1)->Unit(benchmark::kSecond);
BENCHMARK(BM_ComakTrialCoarseInertiaShank)->Iterations(1)->Unit(benchmark::kSecond);
BENCHMARK(BM_ComakTrialMediumInertiaShank)->Iterations(1)->Unit(benchmark::kSecond);

}  // namespace

BENCHMARK_MAIN();
