#pragma once
// Sums whose bits do not depend on the number of threads: the values are
// summed in fixed blocks of 4096 (each block in index order), then the block
// sums in block order. Used for every global quantity (energies, volumes).
#include <cstdint>
#include <vector>

namespace arthrosim::shockwave {

/// Loops over fewer items than this run on one thread: on a shared machine a
/// parallel region costs far more than a small loop (a descheduled thread
/// stalls the barrier).
constexpr std::int64_t kParallelMin = 16384;

/// Sum of f(i) for i in [0, n), deterministic for any thread count.
template <typename F>
double deterministic_sum(std::int64_t n, F f) {
  constexpr std::int64_t kBlock = 4096;
  const std::int64_t blocks = (n + kBlock - 1) / kBlock;
  std::vector<double> partial(static_cast<size_t>(blocks), 0.0);
#pragma omp parallel for schedule(static) if (n >= kParallelMin)
  for (std::int64_t b = 0; b < blocks; ++b) {
    double s = 0.0;
    const std::int64_t end = (b + 1) * kBlock < n ? (b + 1) * kBlock : n;
    for (std::int64_t i = b * kBlock; i < end; ++i) s += f(i);
    partial[static_cast<size_t>(b)] = s;
  }
  double total = 0.0;
  for (double p : partial) total += p;
  return total;
}

}  // namespace arthrosim::shockwave
