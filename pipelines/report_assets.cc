#include "pipelines/report_assets.h"

// The assembler's .incbin copies the vendored file into read-only data; the
// path comes from pipelines/CMakeLists.txt (ARTHROSIM_PLOTLY_JS), which also
// makes this file depend on it. A NUL byte follows the data but is not part
// of the view.
#ifndef ARTHROSIM_PLOTLY_JS
#error "ARTHROSIM_PLOTLY_JS (path of plotly-gl3d.min.js) is set by pipelines/CMakeLists.txt"
#endif

asm(".section .rodata\n"
    ".balign 16\n"
    ".global arthrosim_plotly_js_begin\n"
    ".hidden arthrosim_plotly_js_begin\n"
    "arthrosim_plotly_js_begin:\n"
    ".incbin \"" ARTHROSIM_PLOTLY_JS "\"\n"
    ".global arthrosim_plotly_js_end\n"
    ".hidden arthrosim_plotly_js_end\n"
    "arthrosim_plotly_js_end:\n"
    ".byte 0\n"
    ".previous\n");

extern "C" const char arthrosim_plotly_js_begin[];
extern "C" const char arthrosim_plotly_js_end[];

namespace arthrosim::pipelines::report_html {

std::string_view plotly_js() {
  return std::string_view(arthrosim_plotly_js_begin,
                          static_cast<std::size_t>(arthrosim_plotly_js_end - arthrosim_plotly_js_begin));
}

}  // namespace arthrosim::pipelines::report_html
