#pragma once
// Renders a report.html in headless Chromium (Debian package `chromium`,
// scripts/install-deps.sh) and returns what the page's own check wrote into
// <pre id="report-check"> after drawing every figure (pipelines/report_html.h):
// {"ok": ..., "figures": N, "failed": [...], "errors": [...]}.
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>

namespace arthrosim::testing {

/// Chromium's executable: $ARTHROSIM_CHROMIUM, else chromium on the PATH; empty
/// when there is none (tests then skip, saying so).
inline std::string chromium_path() {
  if (const char* env = std::getenv("ARTHROSIM_CHROMIUM"); env && *env) return env;
  for (const char* name : {"chromium", "chromium-browser"}) {
    const std::string cmd = std::string("command -v ") + name + " >/dev/null 2>&1";
    if (std::system(cmd.c_str()) == 0) return name;
  }
  return "";
}

inline constexpr const char* kNoChromium =
    "chromium is not installed (Debian package chromium, scripts/install-deps.sh): the report is not rendered";

/// Chromium's command line for `page` (a file path). WebGL (the 3D views) is
/// drawn by SwiftShader, the software renderer; --no-sandbox because CI runs as
/// root; a profile folder of its own so runs never share state.
inline std::string chromium_command(const std::string& chromium, const std::filesystem::path& page,
                                    const std::filesystem::path& profile, const std::string& action) {
  return "timeout 120 " + chromium + " --headless --no-sandbox --no-first-run --disable-extensions" +
         " --use-angle=swiftshader --enable-unsafe-swiftshader --hide-scrollbars" +
         " --user-data-dir=" + profile.string() + " --virtual-time-budget=20000 --window-size=1280,900 " + action +
         " file://" + std::filesystem::absolute(page).string();
}

/// The text of <pre id="report-check"> after Chromium ran the page; empty if
/// Chromium failed or the page never wrote its check.
inline std::string render_check(const std::string& chromium, const std::filesystem::path& page) {
  const auto dir = std::filesystem::absolute(page).parent_path();
  const auto dom = dir / "report.dom.html", log = dir / "report.chromium.log";
  const std::string cmd = chromium_command(chromium, page, dir / "chromium-profile", "--dump-dom") + " > " +
                          dom.string() + " 2> " + log.string();
  if (std::system(cmd.c_str()) != 0) return "";
  std::ifstream in(dom);
  std::stringstream ss;
  ss << in.rdbuf();
  const std::string text = ss.str();
  const std::string open = "id=\"report-check\"";
  const auto at = text.find(open);
  if (at == std::string::npos) return "";
  const auto start = text.find('>', at);
  const auto end = text.find("</pre>", start);
  if (start == std::string::npos || end == std::string::npos) return "";
  return text.substr(start + 1, end - start - 1);
}

}  // namespace arthrosim::testing
