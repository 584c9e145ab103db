#pragma once
// Command-line items of the form NAME=VALUE (arthrosim-comak --muscle-weight,
// arthrosim-prepare --surface-edge-length-mm, arthrosim run --set). The value's range is the
// caller's (or its library's) to check.
#include <cstdlib>
#include <string>
#include <utility>

#include "common/error.h"

namespace arthrosim::pipelines {

/// NAME=VALUE -> (NAME, VALUE) as text; throws common::InputError naming the
/// option, the expected form (e.g. "KEY=VALUE") and the item when there is
/// no '=', no name or no value.
inline std::pair<std::string, std::string> split_name_value(const std::string& item, const std::string& option,
                                                            const std::string& form = "NAME=VALUE") {
  const size_t eq = item.find('=');
  if (eq == std::string::npos || eq == 0 || eq + 1 == item.size())
    throw common::InputError(option + ": expected " + form + ", found '" + item + "'");
  return {item.substr(0, eq), item.substr(eq + 1)};
}

/// NAME=VALUE -> (NAME, VALUE); as split_name_value, and VALUE must be a number.
inline std::pair<std::string, double> parse_name_value(const std::string& item, const std::string& option) {
  const auto [name, text] = split_name_value(item, option);
  char* end = nullptr;
  const double v = std::strtod(text.c_str(), &end);
  if (end == text.c_str() || *end != 0)
    throw common::InputError(option + ": expected NAME=VALUE, found '" + item + "'");
  return {name, v};
}

}  // namespace arthrosim::pipelines
