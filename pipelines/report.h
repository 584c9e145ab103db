#pragma once
// Text helpers shared by arthrosim's HTML pages (the post report,
// pipelines/report_html.h; the study report): XML-safe escaping and a compact
// number format (JSON: pipelines/json.h).
#include <string>

#include "pipelines/json.h"

namespace arthrosim::pipelines::report {

/// &, <, >, " and ' escaped for XML text and attribute values.
std::string escape(const std::string& text);
/// Shortest round-trip-ish decimal for tables/JSON ("%.6g"); NaN/Inf -> "null".
std::string number(double value);

/// The JSON writer (pipelines/json.h).
using Json = json::Writer;

}  // namespace arthrosim::pipelines::report
