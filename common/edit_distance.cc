#include "common/edit_distance.h"

#include <algorithm>

namespace arthrosim::common {

std::size_t edit_distance(std::string_view a, std::string_view b) {
  std::vector<std::size_t> prev(b.size() + 1), cur(b.size() + 1);
  for (std::size_t j = 0; j <= b.size(); ++j) prev[j] = j;
  for (std::size_t i = 1; i <= a.size(); ++i) {
    cur[0] = i;
    for (std::size_t j = 1; j <= b.size(); ++j) {
      cur[j] = std::min({prev[j] + 1, cur[j - 1] + 1, prev[j - 1] + (a[i - 1] != b[j - 1])});
    }
    std::swap(prev, cur);
  }
  return prev[b.size()];
}

std::string closest_match(std::string_view word, const std::vector<std::string_view>& candidates,
                          std::size_t max_distance) {
  std::string_view best;
  std::size_t best_d = max_distance;
  for (std::string_view c : candidates) {
    const std::size_t d = edit_distance(word, c);
    if (d < best_d) {
      best_d = d;
      best = c;
    }
  }
  return std::string(best);
}

std::string closest_match(std::string_view word, const std::vector<std::string>& candidates,
                          std::size_t max_distance) {
  return closest_match(word, std::vector<std::string_view>(candidates.begin(), candidates.end()), max_distance);
}

std::string did_you_mean(std::string_view word, const std::vector<std::string_view>& candidates,
                         std::size_t max_distance) {
  const std::string best = closest_match(word, candidates, max_distance);
  return best.empty() ? std::string() : " (did you mean '" + best + "'?)";
}

}  // namespace arthrosim::common
