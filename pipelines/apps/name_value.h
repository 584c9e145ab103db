#pragma once
// Command-line items of the form NAME=VALUE (arthrosim-comak --muscle-weight,
// arthrosim-prepare --surface-edge-length-mm). The value's range is the
// caller's (or its library's) to check.
#include <cstdlib>
#include <string>
#include <utility>

#include "common/error.h"

namespace arthrosim::pipelines {

/// NAME=VALUE -> (NAME, VALUE); throws common::InputError naming the option
/// and the item when there is no '=', no name, or VALUE is not a number.
inline std::pair<std::string, double> parse_name_value(const std::string& item, const std::string& option) {
  const size_t eq = item.find('=');
  char* end = nullptr;
  const double v = eq == std::string::npos ? 0.0 : std::strtod(item.c_str() + eq + 1, &end);
  if (eq == std::string::npos || eq == 0 || !end || end == item.c_str() + eq + 1 || *end != 0)
    throw common::InputError(option + ": expected NAME=VALUE, found '" + item + "'");
  return {item.substr(0, eq), v};
}

}  // namespace arthrosim::pipelines
