#pragma once
// Files the report needs at view time, embedded in the program at build time
// so that a report can be written anywhere (pipelines/report_html.h).
#include <string_view>

namespace arthrosim::pipelines::report_html {

/// third_party/plotly.js-gl3d-dist-min/plotly-gl3d.min.js, byte for byte.
std::string_view plotly_js();

}  // namespace arthrosim::pipelines::report_html
