#pragma once
// Levenshtein edit distance and the "did you mean" hint built on it, for
// every message that names an unknown word (scene keys, effects, dotted keys,
// scenario names).
#include <cstddef>
#include <string>
#include <string_view>
#include <vector>

namespace arthrosim::common {

/// Insertions, deletions and substitutions turning a into b.
std::size_t edit_distance(std::string_view a, std::string_view b);

/// The candidate closest to `word` if its distance is below `max_distance`
/// (first of equals in the given order), else "".
std::string closest_match(std::string_view word, const std::vector<std::string_view>& candidates,
                          std::size_t max_distance = 4);
std::string closest_match(std::string_view word, const std::vector<std::string>& candidates,
                          std::size_t max_distance = 4);

/// " (did you mean 'x'?)" for closest_match(), or "".
std::string did_you_mean(std::string_view word, const std::vector<std::string_view>& candidates,
                         std::size_t max_distance = 4);

}  // namespace arthrosim::common
