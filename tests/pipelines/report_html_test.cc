// The report renderer (pipelines/report_html.h): number formatting, the page's
// structure (well-formed XML, ids, summary links, units on every axis, stage
// line styles, legends outside the data), models it refuses, the embedded
// plotly.js, and the page drawn in headless Chromium: every kind of figure
// draws (its own check in the page), and a page without plotly.js says so.
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <numbers>
#include <sstream>

#include "pipelines/report_assets.h"
#include "pipelines/report_html.h"
#include "tests/pipelines/chromium_check.h"

namespace arthrosim::pipelines::report_html {
namespace {

namespace fs = std::filesystem;
const fs::path kDir = fs::path(ARTHROSIM_BINARY_DIR) / "report_html_test";

std::string slurp(const fs::path& p) {
  std::ifstream in(p, std::ios::binary);
  std::stringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

// A report with one block of every kind: a gait-like force of two stages, a
// limit line, a 2D map (outline, direction segments, coloured points with two
// without a value), a 3D surface (a hemisphere cap) with two fields, a table
// and a summary linking to them.
Report every_kind() {
  Report r;
  r.title = "arthrosim test report";
  r.header = {"Scene: test"};
  r.banner = "Test data <&> only";
  LinePlot tp;
  tp.id = "fig-force", tp.title = "Tibiofemoral contact force", tp.caption = "two stages";
  tp.x_label = "time [s]", tp.y_label = "force [BW]";
  Line s1, s2, lim;
  for (int k = 0; k <= 100; ++k) {
    const double t = k / 100.0, f = 3 * std::exp(-std::pow((t - 0.15) / 0.07, 2)) + 2.8 * std::exp(-std::pow((t - 0.5) / 0.07, 2));
    s1.x.push_back(t), s1.y.push_back(f);
    s2.x.push_back(t), s2.y.push_back(1.05 * f);
  }
  s1.label = "total |F|", s1.group = "stage 1", s1.dash = Dash::kSolid;
  s2.label = "total |F|", s2.group = "stage 2", s2.dash = Dash::kDash;
  lim.label = "limit", lim.x = {0, 1}, lim.y = {3.5, 3.5}, lim.dash = Dash::kDot, lim.colour = -1;
  tp.lines = {s1, s2, lim};

  MapPlot mp;
  mp.id = "fig-map", mp.title = "Directions and error", mp.caption = "map";
  Polyline outline;
  outline.label = "outline", outline.colour = -1;
  outline.points.resize(40, 2);
  for (int i = 0; i < 40; ++i)
    outline.points.row(i) << 25 * std::cos(2 * std::numbers::pi * i / 40), 16 * std::sin(2 * std::numbers::pi * i / 40);
  Segments seg;
  seg.label = "model lines";
  Points pts;
  pts.label = "angle error", pts.unit = "deg", pts.lo = 0, pts.hi = 90;
  const int n = 30;
  seg.centres.resize(n, 2), seg.angle_rad.resize(n), seg.length.setConstant(n, 2.0);
  pts.xy.resize(n, 2), pts.values.resize(n);
  for (int i = 0; i < n; ++i) {
    seg.centres.row(i) << -15 + i, 5 * std::sin(i / 3.0);
    seg.angle_rad(i) = 0.1 * i;
    pts.xy.row(i) = seg.centres.row(i);
    pts.values(i) = i < 2 ? std::nan("") : 3.0 * i;
  }
  mp.outlines = {outline};
  mp.segments = {seg};
  mp.points = {pts};

  SurfacePlot sp;
  sp.id = "fig-surface", sp.title = "Deflection on the surface", sp.caption = "3D";
  const int m = 12;
  sp.nodes_mm.resize((m + 1) * (m + 1), 3);
  for (int a = 0; a <= m; ++a)
    for (int b = 0; b <= m; ++b) {
      const double x = -20 + 40.0 * a / m, y = -20 + 40.0 * b / m;
      sp.nodes_mm.row(a * (m + 1) + b) << x, y, std::sqrt(std::max(0.0, 900 - x * x - y * y));
    }
  sp.triangles.resize(2 * m * m, 3);
  for (int a = 0; a < m; ++a)
    for (int b = 0; b < m; ++b) {
      const int k = a * (m + 1) + b;
      sp.triangles.row(2 * (a * m + b)) << k, k + 1, k + m + 2;
      sp.triangles.row(2 * (a * m + b) + 1) << k, k + m + 2, k + m + 1;
    }
  Field defl{"deflection, first peak", "mm", {}}, e1{"e1, first peak", "strain", {}};
  for (Eigen::Index i = 0; i < sp.nodes_mm.rows(); ++i) {
    defl.values.push_back(-0.01 * sp.nodes_mm(i, 2));
    e1.values.push_back(0.001 * sp.nodes_mm(i, 0));
  }
  sp.fields = {defl, e1};

  Table tb;
  tb.id = "tab-rule", tb.title = "Accuracy rule";
  tb.header = {"scenario", "steps", "max ratio"};
  tb.rows = {{std::string("gait"), 42LL, 0.0389972}, {std::string("gait_osmotic"), 41LL, 69.2579}};

  r.summary = {{"stage 1 first peak", "3 BW", "2-3.5 BW", Verdict::kPass, "fig-force"},
               {"accuracy rule", "0.039", "<= 0.1", Verdict::kFail, "tab-rule"},
               {"angle", "20 deg", "seed: visual", Verdict::kInfo, ""}};
  r.sections = {{"sec-stage1", "Contact force", {Text{"Forces of both stages.", {}, false}, tp}},
                {"sec-maps", "Maps", {mp, sp, tb, Text{"", {"missing: nothing"}, true}}}};
  return r;
}

TEST(ReportHtml, SignificantDigits) {
  // The raw values, and the edges of the notation switch.
  EXPECT_EQ(significant(1474.5), "1470");  // %.2e rounds half to even on the binary value
  EXPECT_EQ(significant(982.999), "983");
  EXPECT_EQ(significant(-1.73472e-17), "-1.73e-17");
  EXPECT_EQ(significant(0.841487), "0.841");
  EXPECT_EQ(significant(69.2579), "69.3");
  EXPECT_EQ(significant(0.0389972), "0.039");
  EXPECT_EQ(significant(999.6), "1000");
  EXPECT_EQ(significant(0.5), "0.5");
  EXPECT_EQ(significant(0), "0");
  EXPECT_EQ(significant(123456789.0), "1.23e8");
  EXPECT_EQ(significant(2.5e-5), "2.5e-5");
  EXPECT_EQ(significant(std::nan("")), "-");
  EXPECT_EQ(significant(3.14159, 2), "3.1");
}

TEST(ReportHtml, PageStructure) {
  const Report r = every_kind();
  const std::string h = render(r);
  EXPECT_EQ(figure_ids(r), (std::vector<std::string>{"fig-force", "fig-map", "fig-surface"}));
  // Axis titles carry units; stage 2 dashed, stage 1 solid; legend right of the axes.
  for (const char* s : {"\"text\": \"time [s]\"", "\"text\": \"force [BW]\"", "\"text\": \"view right [mm]\"",
                        "\"text\": \"model z [mm]\"", "\"dash\": \"dash\"", "\"dash\": \"solid\"", "\"dash\": \"dot\"",
                        "\"x\": 1.02", "\"legendgrouptitle\"", "\"type\": \"mesh3d\"", "\"updatemenus\"",
                        "\"scaleanchor\": \"y\""})
    EXPECT_NE(h.find(s), std::string::npos) << s;
  // Table numbers with three significant digits, integers exact.
  EXPECT_NE(h.find(">0.039</td>"), std::string::npos);
  EXPECT_NE(h.find(">69.3</td>"), std::string::npos);
  EXPECT_NE(h.find(">42</td>"), std::string::npos);
  EXPECT_EQ(h.find("69.2579"), std::string::npos);
  // Summary: pass/fail marks and links to figures; labels escaped everywhere.
  EXPECT_NE(h.find("class=\"pass\""), std::string::npos);
  EXPECT_NE(h.find("class=\"fail\""), std::string::npos);
  EXPECT_NE(h.find("<a href=\"#fig-force\">"), std::string::npos);
  EXPECT_NE(h.find("Test data &lt;&amp;&gt; only"), std::string::npos);
  // Well-formed XML with unique ids (Python's parser).
  fs::create_directories(kDir);
  std::ofstream(kDir / "page.html") << h;
  const std::string cmd = "/usr/bin/python3 -c \"import sys, xml.etree.ElementTree as E; r = E.parse(sys.argv[1]).getroot(); "
                          "ids = [e.get('id') for e in r.iter() if e.get('id')]; assert len(ids) == len(set(ids)), ids\" " +
                          (kDir / "page.html").string();
  EXPECT_EQ(std::system(cmd.c_str()), 0);
}

TEST(ReportHtml, RefusesModelsItCannotDrawHonestly) {
  Report r = every_kind();
  std::get<LinePlot>(r.sections[0].blocks[1]).y_label.clear();
  EXPECT_THROW(render(r), std::invalid_argument);  // an axis without a label
  r = every_kind();
  r.summary[0].figure = "fig-none";
  EXPECT_THROW(render(r), std::invalid_argument);  // a summary link to nothing
  r = every_kind();
  std::get<SurfacePlot>(r.sections[1].blocks[1]).fields[0].values.pop_back();
  EXPECT_THROW(render(r), std::invalid_argument);  // a field of the wrong size
  r = every_kind();
  std::get<MapPlot>(r.sections[1].blocks[0]).id = "fig-force";
  EXPECT_THROW(render(r), std::invalid_argument);  // a duplicate id
}

TEST(ReportHtml, WritesThePageAndTheEmbeddedPlotly) {
  const fs::path dir = kDir / "write";
  const fs::path page = write(every_kind(), dir);
  EXPECT_EQ(page, dir / "report.html");
  const std::string vendored =
      slurp(fs::path(ARTHROSIM_SOURCE_DIR) / "third_party/plotly.js-gl3d-dist-min/plotly-gl3d.min.js");
  ASSERT_GT(vendored.size(), 1000000u);
  EXPECT_EQ(plotly_js().size(), vendored.size());
  EXPECT_TRUE(slurp(dir / kPlotlyFile) == vendored);  // byte for byte
  EXPECT_NE(slurp(page).find("<script src=\"plotly-gl3d.min.js\">"), std::string::npos);
}

// Every figure draws in a real browser: the page's own check (after
// Plotly.newPlot of every figure) finds no script error and every figure
// element with a non-zero size, its SVG traces or its WebGL canvas present.
TEST(ReportHtml, EveryFigureDrawsInHeadlessChromium) {
  const std::string chromium = arthrosim::testing::chromium_path();
  if (chromium.empty()) GTEST_SKIP() << arthrosim::testing::kNoChromium;
  const fs::path page = write(every_kind(), kDir / "chromium");
  const std::string check = arthrosim::testing::render_check(chromium, page);
  EXPECT_EQ(check, "{\"ok\":true,\"figures\":3,\"failed\":[],\"errors\":[]}")
      << "see " << (kDir / "chromium" / "report.chromium.log");
}

// The check can fail: without plotly.js next to it, the page reports every
// figure as not drawn (and shows the reason in its banner).
TEST(ReportHtml, PageWithoutPlotlySaysSo) {
  const std::string chromium = arthrosim::testing::chromium_path();
  if (chromium.empty()) GTEST_SKIP() << arthrosim::testing::kNoChromium;
  const fs::path page = write(every_kind(), kDir / "no_plotly");
  fs::remove(kDir / "no_plotly" / kPlotlyFile);
  const std::string check = arthrosim::testing::render_check(chromium, page);
  EXPECT_NE(check.find("\"ok\":false"), std::string::npos) << check;
  EXPECT_NE(check.find("\"failed\":[\"fig-force\",\"fig-map\",\"fig-surface\"]"), std::string::npos) << check;
  EXPECT_NE(check.find("was not loaded"), std::string::npos) << check;
}

}  // namespace
}  // namespace arthrosim::pipelines::report_html
