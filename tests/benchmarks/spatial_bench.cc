// TriangleTree timings on a ~30k-triangle cartilage-like patch: tree build,
// cold ray queries (first_hit through the tree), hinted queries (hit_triangle on
// the triangle hit last time, as the contact code does between Newton
// iterations, falling back to first_hit on a miss), closest point, box query.
//
//   build/bench/spatial_bench --benchmark_min_time=0.5
#include <benchmark/benchmark.h>

#include <random>
#include <vector>

#include "common/spatial.h"
#include "tests/common/test_meshes.h"

namespace arthrosim::common {
namespace {

// 40 x 40 mm patch with a 4 mm dome, 122 x 123 quads = 30012 triangles (0.33 mm edges).
const TriangleMesh& patch() {
  static const TriangleMesh m = testing::curved_patch(122, 123, 0.04, 0.04, 0.004);
  return m;
}

struct RaySet {
  std::vector<Vec3> origins;
  Vec3 direction{0, 0, -1};
};

// Vertical rays from 10 mm above, over the central 90 % of the patch.
RaySet rays(int n, unsigned seed, double shift = 0.0) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> u(0.002, 0.038);
  RaySet r;
  for (int i = 0; i < n; ++i) r.origins.emplace_back(u(rng) + shift, u(rng), 0.014);
  return r;
}

void BM_TreeBuild(benchmark::State& state) {
  for (auto _ : state) {
    TriangleTree tree(patch());
    benchmark::DoNotOptimize(tree);
  }
  state.counters["triangles"] = patch().num_triangles();
}
BENCHMARK(BM_TreeBuild)->Unit(benchmark::kMillisecond);

void BM_FirstHitCold(benchmark::State& state) {
  const TriangleTree tree(patch());
  const RaySet r = rays(4096, 1);
  size_t i = 0, hits = 0;
  for (auto _ : state) {
    const auto h = tree.first_hit(r.origins[i++ & 4095], r.direction);
    hits += h.has_value();
    benchmark::DoNotOptimize(h);
  }
  state.counters["hit_rate"] = static_cast<double>(hits) / static_cast<double>(state.iterations());
  state.SetItemsProcessed(state.iterations());
}
BENCHMARK(BM_FirstHitCold);

// Hinted: the triangles hit by rays 1 um away (a small pose change) are cached;
// each query tests the cached triangle first and falls back to the tree.
void BM_FirstHitHinted(benchmark::State& state) {
  const TriangleTree tree(patch());
  const RaySet before = rays(4096, 1, -1e-6), now = rays(4096, 1);
  std::vector<int> cache(4096, -1);
  for (int k = 0; k < 4096; ++k) {
    const auto h = tree.first_hit(before.origins[k], before.direction);
    cache[k] = h ? h->triangle : -1;
  }
  size_t i = 0, reused = 0;
  for (auto _ : state) {
    const size_t k = i++ & 4095;
    std::optional<RayHit> h;
    if (cache[k] >= 0) h = tree.hit_triangle(cache[k], now.origins[k], now.direction);
    if (h) {
      ++reused;
    } else {
      h = tree.first_hit(now.origins[k], now.direction);
    }
    benchmark::DoNotOptimize(h);
  }
  state.counters["cache_reuse"] = static_cast<double>(reused) / static_cast<double>(state.iterations());
  state.SetItemsProcessed(state.iterations());
}
BENCHMARK(BM_FirstHitHinted);

void BM_ClosestPoint(benchmark::State& state) {
  const TriangleTree tree(patch());
  std::mt19937_64 rng(2);
  std::uniform_real_distribution<double> u(0.0, 0.04), z(-0.002, 0.008);
  std::vector<Vec3> pts;
  for (int i = 0; i < 4096; ++i) pts.emplace_back(u(rng), u(rng), z(rng));
  size_t i = 0;
  for (auto _ : state) benchmark::DoNotOptimize(tree.closest_point(pts[i++ & 4095]));
  state.SetItemsProcessed(state.iterations());
}
BENCHMARK(BM_ClosestPoint);

void BM_TrianglesInBox2mm(benchmark::State& state) {
  const TriangleTree tree(patch());
  const RaySet r = rays(4096, 3);
  size_t i = 0;
  for (auto _ : state) {
    const Vec3 c = r.origins[i++ & 4095] - Vec3(0, 0, 0.012);
    benchmark::DoNotOptimize(tree.triangles_in_box(c - Vec3::Constant(0.001), c + Vec3::Constant(0.001)));
  }
  state.SetItemsProcessed(state.iterations());
}
BENCHMARK(BM_TrianglesInBox2mm);

}  // namespace
}  // namespace arthrosim::common

BENCHMARK_MAIN();
