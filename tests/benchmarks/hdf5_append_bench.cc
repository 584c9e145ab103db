// Cost of crash-safe frame appending (two H5Fflush per frame, see
// common/hdf5.h) against plain whole-dataset writes, for frames of n_nodes x 3
// doubles (a deforming surface).
#include <benchmark/benchmark.h>

#include <filesystem>

#include "common/hdf5.h"

namespace {

using arthrosim::common::H5File;

std::string bench_file(const char* name) {
  return (std::filesystem::temp_directory_path() / name).string();
}

void BM_AppendFrame(benchmark::State& state) {
  const auto n_nodes = state.range(0);
  const std::string path = bench_file("arthrosim_append_bench.h5");
  H5File f(path, H5File::Mode::kTruncate);
  {
    // Capacity grows by doubling (expected_frames unknown), as in a run of
    // unknown length.
    auto app = f.appender("X", {n_nodes, 3});
    const Eigen::MatrixXd frame = Eigen::MatrixXd::Constant(n_nodes, 3, 0.5);
    for (auto _ : state) app.append(frame);
  }
  std::filesystem::remove(path);
  state.SetBytesProcessed(state.iterations() * n_nodes * 3 * 8);
  state.counters["frames_per_s"] = benchmark::Counter(static_cast<double>(state.iterations()), benchmark::Counter::kIsRate);
}
BENCHMARK(BM_AppendFrame)->Arg(1000)->Arg(10000)->Unit(benchmark::kMicrosecond)->UseRealTime();

void BM_WriteWholeMatrix(benchmark::State& state) {
  const auto n_nodes = state.range(0);
  const std::string path = bench_file("arthrosim_write_bench.h5");
  H5File f(path, H5File::Mode::kTruncate);
  const Eigen::MatrixXd m = Eigen::MatrixXd::Constant(n_nodes, 3, 0.5);
  for (auto _ : state) {
    f.write("X", m);
    f.flush();
  }
  std::filesystem::remove(path);
  state.SetBytesProcessed(state.iterations() * n_nodes * 3 * 8);
}
BENCHMARK(BM_WriteWholeMatrix)->Arg(1000)->Arg(10000)->Unit(benchmark::kMicrosecond)->UseRealTime();

}  // namespace

BENCHMARK_MAIN();
