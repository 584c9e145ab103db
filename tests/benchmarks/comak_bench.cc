// Benchmark of the COMAK stage (issue 4 performance target: <= 1 s per frame
// at the fine resolution on the 2-core machine): the whole bundled SYNTHETIC
// trial (115 frames) on the bundled coarse (knee_coarse.urdf) and medium
// (knee.urdf) models with the default options. Prints, per model: frames,
// converged/failed, seconds per frame (wall and process CPU: the machine is
// shared, so wall time includes waiting), Ipopt iterations per frame (mean,
// median, max), and the tibiofemoral contact-force checks of issue 4 (first
// and second stance peaks in body weights, medial/lateral at the first peak).
//
// Optional: ARTHROSIM_COMAK_BENCH_STRIDE=k uses every k-th frame.
#include <benchmark/benchmark.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <ctime>
#include <string>
#include <vector>

#include "musculoskeletal/comak.h"
#include "musculoskeletal/gait_trial.h"
#include "musculoskeletal/kinematics_file.h"
#include "musculoskeletal/knee_loads.h"
#include "musculoskeletal/model_io.h"

namespace msk = arthrosim::musculoskeletal;

namespace {

void run_trial(benchmark::State& state, const char* model_file) {
  const std::string root = ARTHROSIM_SOURCE_DIR;
  const msk::Model model = msk::load_model(root + "/data/models/knee_parametric/" + model_file);
  const auto trial = msk::load_gait_trial(root + "/data/trials/synthetic_gait");
  const auto loads = msk::compute_knee_loads(trial, msk::leg_model_for_trial(trial));
  int stride = 1;
  if (const char* s = std::getenv("ARTHROSIM_COMAK_BENCH_STRIDE")) stride = std::max(1, std::atoi(s));
  const auto frames = msk::comak_frame_inputs(loads, 0, -1, stride);
  msk::ComakProblem problem(model, {});
  const double bw = trial.body_mass_kg * 9.80665;
  for (auto _ : state) {
    std::vector<int> iters;
    std::vector<double> t, tf, med, lat;
    const std::clock_t c0 = std::clock();
    const auto sum = msk::run_comak(problem, frames, [&](const auto& f, const auto& r, const auto& d) {
      iters.push_back(r.iterations);
      const auto c = msk::tibiofemoral_contact(model, d);
      t.push_back(f.time);
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
                  "second peak %.2f BW at %.2f s\n",
                  tf[i1], t[i1], med[i1], lat[i1], tf[i2], t[i2]);
    for (int f : sum.failed_frames) std::printf("  failed frame %d\n", f);
    state.counters["s_per_frame"] = sum.wall_time / sum.frames;
    state.counters["cpu_s_per_frame"] = cpu / sum.frames;
    state.counters["iterations_per_frame"] = mean_it;
    state.counters["failed"] = sum.failed;
  }
}

void BM_ComakTrialCoarse(benchmark::State& s) { run_trial(s, "knee_coarse.urdf"); }
void BM_ComakTrialMedium(benchmark::State& s) { run_trial(s, "knee.urdf"); }
BENCHMARK(BM_ComakTrialCoarse)->Iterations(1)->Unit(benchmark::kSecond);
BENCHMARK(BM_ComakTrialMedium)->Iterations(1)->Unit(benchmark::kSecond);

}  // namespace

BENCHMARK_MAIN();
