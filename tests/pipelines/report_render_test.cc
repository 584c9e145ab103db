// arthrosim-post's report (pipelines/post_stage.h, pipelines/report_html.h): run on small
// HDF5 inputs written here (surface output of two scenarios, a kinematics file with
// medial/lateral contact force) and the bundled SYNTHETIC map, then check with Python's
// XML parser that report.html is well-formed, that every link resolves, that every plot
// has its figure spec, and that summary.json parses and lists the same figures; then draw
// the report in headless Chromium (every figure draws). A run without optional inputs
// must still write a report that says what is missing.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <numbers>
#include <sstream>

#include "common/hdf5.h"
#include "pipelines/post_stage.h"
#include "pipelines/report.h"
#include "tests/pipelines/chromium_check.h"

namespace arthrosim::pipelines {
namespace {

namespace fs = std::filesystem;
const fs::path kDir = fs::path(ARTHROSIM_BINARY_DIR) / "report_render_test";

// Planar 41 x 31 grid, 50 x 30 mm, z = 0 (normals +z), seen along -z.
// With `walking`, also what a mesh-contact scenario writes (docs/surface_output.md):
// /trial_time (a 0.02 s seating before the trial clock), the tibiofemoral force and
// the per-step accuracy-rule records, the first step without active contacts.
void write_surface(const fs::path& path, double phase, bool walking = false, double t_end = 1.0) {
  const int nx = 40, ny = 30, T = 5;
  Eigen::MatrixXd V((nx + 1) * (ny + 1), 3);
  for (int j = 0; j <= ny; ++j)
    for (int i = 0; i <= nx; ++i) V.row(j * (nx + 1) + i) << -25e-3 + 50e-3 * i / nx, -15e-3 + 30e-3 * j / ny, 0;
  Eigen::MatrixXi Q(nx * ny, 4);
  for (int j = 0; j < ny; ++j)
    for (int i = 0; i < nx; ++i) {
      const int k = j * (nx + 1) + i;
      Q.row(j * nx + i) << k, k + 1, k + nx + 2, k + nx + 1;
    }
  const auto N = V.rows();
  Eigen::MatrixXd e1(T, N), defl(T, N);
  common::Tensor3d dir;
  dir.dims = {T, N, 3};
  dir.data.resize(T * N * 3);
  for (int t = 0; t < T; ++t)
    for (Eigen::Index i = 0; i < N; ++i) {
      const double x = V(i, 0) * 1e3, y = V(i, 1) * 1e3;
      const double th = 0.7 * std::sin(std::numbers::pi * x / 30.0) + 0.4 * y / 16.0 + phase;
      e1(t, i) = 0.01 * (1 + 0.5 * std::sin(t + x / 10));
      defl(t, i) = 1e-4 * t * std::exp(-(x * x + y * y) / 100);
      dir(t, i, 0) = std::cos(th), dir(t, i, 1) = std::sin(th), dir(t, i, 2) = 0;
    }
  common::H5File f(path.string(), common::H5File::Mode::kTruncate);
  f.set_attribute("/", "scenario", "test");
  f.write("/time", Eigen::VectorXd::LinSpaced(T, 0.0, t_end));
  f.write("/surfaces/femur/nodes", V);
  f.write("/surfaces/femur/quads", Q);
  f.write("/surfaces/femur/strain/e1", e1);
  f.write_tensor3("/surfaces/femur/strain/e1_dir", dir);
  f.write("/surfaces/femur/deflection", defl);
  f.create_group("/solver/femur");
  f.set_attribute("/solver/femur", "total_s", 12.5);
  f.set_attribute("/solver/femur", "newton_iterations", 42);
  if (!walking) return;
  const Eigen::VectorXd time = Eigen::VectorXd::LinSpaced(T, 0.0, t_end);
  f.write("/trial_time", Eigen::VectorXd(time.array() - 0.02));
  Eigen::MatrixXd F = Eigen::MatrixXd::Zero(T, 3);
  F.col(2) = Eigen::VectorXd::LinSpaced(T, 100.0, 900.0);
  f.write("/contact/tibiofemoral/force", F);
  f.write("/solver/time", Eigen::VectorXd(time.tail(T - 1)));
  f.write("/solver/penetration_ratio", Eigen::VectorXd((Eigen::VectorXd(4) << 0.5, 0.05, 0.2, 0.08).finished()));
  f.write("/solver/unfaded_penetration_ratio", Eigen::VectorXd((Eigen::VectorXd(4) << 0.4, 0.02, 0.12, 0.05).finished()));
  f.write("/solver/active_contacts", Eigen::VectorXi((Eigen::VectorXi(4) << 0, 10, 12, 9).finished()));  // int, as written
  f.set_attribute("/solver", "penetration_limit", 0.1);
}

void write_kinematics(const fs::path& path) {
  const int T = 101;
  Eigen::VectorXd t = Eigen::VectorXd::LinSpaced(T, 0.0, 1.0);
  Eigen::MatrixXd fm(T, 3), fl(T, 3);
  for (int k = 0; k < T; ++k) {
    // Double-hump stance force (peaks near 15 % and 50 %).
    const double s = 1500 * std::exp(-std::pow((t(k) - 0.15) / 0.07, 2)) + 1300 * std::exp(-std::pow((t(k) - 0.5) / 0.07, 2)) + 300;
    fm.row(k) << 0.1 * s, 0.05 * s, 0.6 * s;
    fl.row(k) << 0, 0, 0.4 * s;
  }
  common::H5File f(path.string(), common::H5File::Mode::kTruncate);
  f.write("/time", t);
  // Layout of docs/kinematics_file.md; cop and area must not be plotted as forces.
  f.write("/contact/tibiofemoral/force", Eigen::MatrixXd(fm + fl));
  f.write("/contact/tibiofemoral/medial_force", fm);
  f.write("/contact/tibiofemoral/lateral_force", fl);
  f.write("/contact/tibiofemoral/cop", Eigen::MatrixXd(Eigen::MatrixXd::Ones(T, 3) * 0.01));
  f.write("/contact/tibiofemoral/area", Eigen::VectorXd(Eigen::VectorXd::Ones(T) * 1e-4));
  f.set_attribute("/", "stage", "comak");
}

// Python check: XML well-formed, ids unique, every #link has an element with that id, the
// plots (<figure> with a plot element) are summary.json's figures in order and each has a
// figure spec with data, the summary block's links resolve, missing inputs are in the text.
int check(const fs::path& dir, int min_figures) {
  const fs::path script = kDir / "check.py";
  std::ofstream(script) << R"PY(
import json, sys, xml.etree.ElementTree as ET
d, need = sys.argv[1], int(sys.argv[2])
root = ET.parse(d + '/report.html').getroot()
H = '{http://www.w3.org/1999/xhtml}'
all_ids = [e.get('id') for e in root.iter() if e.get('id')]
assert len(all_ids) == len(set(all_ids)), ('duplicate ids', all_ids)
ids = {e.get('id'): e for e in root.iter() if e.get('id')}
links = [a.get('href')[1:] for a in root.iter(H + 'a') if (a.get('href') or '').startswith('#')]
for l in links:
    assert l in ids, ('missing link target', l)
plots = [f.get('id') for f in root.iter(H + 'figure') if f.get('class') in ('plot', 'map', 'surface')]
assert len(plots) >= need, ('too few figures', len(plots), need)
specs = json.loads(ids['report-figures'].text)
assert [s['id'] for s in specs] == plots, ('figure specs differ', [s['id'] for s in specs], plots)
for s in specs:
    assert s['data'], ('figure without data', s['id'])
s = json.load(open(d + '/summary.json'))
assert s['figures'] == plots, ('summary figures differ', s['figures'], plots)
text = ''.join(root.itertext())
for m in s['missing']:
    assert m in text, ('missing input not reported', m)
print('ok', len(plots), 'figures,', len(s['missing']), 'missing')
)PY";
  const std::string cmd = "/usr/bin/python3 " + script.string() + " " + dir.string() + " " + std::to_string(min_figures);
  return std::system(cmd.c_str());
}

std::string slurp(const fs::path& p) {
  std::ifstream in(p);
  std::stringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

TEST(ReportRender, FullReportIsWellFormedAndComplete) {
  fs::create_directories(kDir);
  write_surface(kDir / "surface_osmotic.h5", 0.0);
  write_surface(kDir / "surface_gait.h5", 0.3, /*walking=*/true);
  write_kinematics(kDir / "kinematics.h5");
  PostInputs in;
  in.surfaces = {{"osmotic", (kDir / "surface_osmotic.h5").string()}, {"gait", (kDir / "surface_gait.h5").string()}};
  in.kinematics = (kDir / "kinematics.h5").string();
  PostOptions opt;
  opt.view = ViewOptions{};  // along -z, y up: the grid's own plane
  opt.splitline_map = std::string(ARTHROSIM_SOURCE_DIR) + "/data/splitlines/synthetic_femur.csv";
  const PostSummary s = run_post(in, opt, (kDir / "full").string());
  // contact + accuracy rule + 2 x (3 key frames x (deflection + e1) + 3D surface + directions + overlay + error)
  EXPECT_EQ(s.figures.size(), 2u + 2u * (6u + 4u));
  ASSERT_EQ(s.scenarios.size(), 2u);
  EXPECT_TRUE(s.missing.empty());
  EXPECT_EQ(check(kDir / "full", 20), 0);
  const std::string html = slurp(kDir / "full" / "report.html");
  EXPECT_NE(html.find("SYNTHETIC"), std::string::npos);
  EXPECT_NE(html.find("first peak"), std::string::npos);  // key frames from the force peaks
  const std::string json = slurp(kDir / "full" / "summary.json");
  EXPECT_NE(json.find("\"label\": \"stage 1 medial_force |F|\""), std::string::npos);
  EXPECT_EQ(json.find("stage 1 cop"), std::string::npos);
  EXPECT_EQ(json.find("stage 1 area"), std::string::npos);
  EXPECT_NE(json.find("\"label\": \"stage 2 gait force |F|\""), std::string::npos);
  // In the page: the force legend groups by stage, stage 2 dashed.
  EXPECT_NE(html.find("\"name\": \"medial_force |F|\""), std::string::npos);
  EXPECT_NE(html.find("\"legendgroup\": \"stage 2 gait\""), std::string::npos);
  EXPECT_NE(html.find("\"dash\": \"dash\""), std::string::npos);
  EXPECT_NE(html.find("total_s"), std::string::npos);     // solver statistics table
  // The summary block: the accuracy rule fails (one step over 0.1), linked to its plot.
  EXPECT_NE(html.find("<a href=\"#fig-accuracy-rule\">"), std::string::npos);
  EXPECT_NE(html.find("class=\"fail\""), std::string::npos);
  // The accuracy rule over the three steps in contact (0.05, 0.2, 0.08; the first
  // step's 0.5 has no active contact and is not counted).
  for (const char* item : {"\"steps_in_contact\": 3", "\"median_ratio\": 0.08", "\"max_ratio\": 0.2",
                           "\"limit\": 0.1", "\"steps_over_limit\": 1",
                           // The same over unfaded contacts (0.02, 0.12, 0.05).
                           "\"median_unfaded_ratio\": 0.05", "\"max_unfaded_ratio\": 0.12",
                           "\"steps_over_limit_unfaded\": 1"})
    EXPECT_NE(json.find(item), std::string::npos) << item;
  EXPECT_NE(html.find("Accuracy rule of the mesh contact"), std::string::npos);
  // Key frames of the walking scenario on the trial clock (/trial_time =
  // /time - 0.02 s): the first peak's frame is the one at 0.25 - 0.02 s.
  EXPECT_NE(json.find("\"name\": \"first peak\",\n          \"time_s\": 0.23"), std::string::npos) << json.substr(0, 3000);
  // The gait field is the osmotic one turned by 0.3 rad = 17.2 deg, so its mean error
  // is larger; the grid's outline is a rectangle, not the map's outline, so only the
  // ordering is asserted here (the known-answer bound is post_synthetic_test).
  EXPECT_LT(s.scenarios[0].stats.front().mean_deg, s.scenarios[1].stats.front().mean_deg);
}

// A walk that ends before the second peak (as the demo's, which stops at mid
// stance) gets maps only at the key frames it covers; the others are listed as
// missing with the span the run covers, never drawn at the nearest frame.
TEST(ReportRender, KeyFramesOutsideTheRunAreReportedNotDrawn) {
  fs::create_directories(kDir);
  write_surface(kDir / "surface_short.h5", 0.3, /*walking=*/true, /*t_end=*/0.3);
  write_kinematics(kDir / "kinematics.h5");
  PostInputs in;
  in.surfaces = {{"gait", (kDir / "surface_short.h5").string()}};
  in.kinematics = (kDir / "kinematics.h5").string();
  PostOptions opt;
  opt.view = ViewOptions{};
  opt.splitline_map = std::string(ARTHROSIM_SOURCE_DIR) + "/data/splitlines/synthetic_femur.csv";
  const PostSummary s = run_post(in, opt, (kDir / "short").string());
  // Trial clock -0.02 .. 0.28 s: the first peak (0.15 s) is covered, mid-stance
  // (about 0.33 s) and the second peak (0.5 s) are not.
  // contact + accuracy rule + 1 key frame x (deflection + e1) + 3D surface + directions + overlay + error
  EXPECT_EQ(s.figures.size(), 2u + 2u + 4u);
  ASSERT_EQ(s.missing.size(), 2u);
  EXPECT_NE(s.missing[0].find("not the mid-stance"), std::string::npos) << s.missing[0];
  EXPECT_NE(s.missing[1].find("not the second peak at 0.5 s"), std::string::npos) << s.missing[1];
  EXPECT_EQ(check(kDir / "short", 7), 0);
}

TEST(ReportRender, MissingOptionalInputsAreReportedNotFatal) {
  fs::create_directories(kDir);
  write_surface(kDir / "surface_only.h5", 0.0);
  PostInputs in;
  in.surfaces = {{"osmotic", (kDir / "surface_only.h5").string()}};
  PostOptions opt;
  opt.view = ViewOptions{};
  const PostSummary s = run_post(in, opt, (kDir / "partial").string());
  EXPECT_EQ(s.missing.size(), 3u);  // kinematics, map, stage-2 contact
  EXPECT_EQ(check(kDir / "partial", 3), 0);
  const PostSummary e = run_post(PostInputs{}, PostOptions{}, (kDir / "empty").string());
  EXPECT_EQ(e.missing.size(), 3u);  // surfaces, kinematics, map
  EXPECT_TRUE(e.figures.empty());
  EXPECT_EQ(check(kDir / "empty", 0), 0);
}

// The full report drawn in a real browser: every figure draws (the page's own
// check after Plotly.newPlot: no script error, every figure element of non-zero
// size with its SVG traces or WebGL canvas).
TEST(ReportRender, FullReportDrawsInHeadlessChromium) {
  const std::string chromium = arthrosim::testing::chromium_path();
  if (chromium.empty()) GTEST_SKIP() << arthrosim::testing::kNoChromium;
  fs::create_directories(kDir);
  write_surface(kDir / "surface_osmotic.h5", 0.0);
  write_surface(kDir / "surface_gait.h5", 0.3, /*walking=*/true);
  write_kinematics(kDir / "kinematics.h5");
  PostInputs in;
  in.surfaces = {{"osmotic", (kDir / "surface_osmotic.h5").string()}, {"gait", (kDir / "surface_gait.h5").string()}};
  in.kinematics = (kDir / "kinematics.h5").string();
  PostOptions opt;
  opt.view = ViewOptions{};
  opt.splitline_map = std::string(ARTHROSIM_SOURCE_DIR) + "/data/splitlines/synthetic_femur.csv";
  const PostSummary s = run_post(in, opt, (kDir / "drawn").string());
  const std::string check = arthrosim::testing::render_check(chromium, s.report_path);
  EXPECT_EQ(check, "{\"ok\":true,\"figures\":" + std::to_string(s.figures.size()) + ",\"failed\":[],\"errors\":[]}")
      << "see " << (kDir / "drawn" / "report.chromium.log");
}

TEST(ReportRender, JsonAndEscaping) {
  report::Json j;
  j.begin_object().value("a\"b", "x<y>&").array("v", std::vector<double>{1.5, std::nan("")}).end_object();
  EXPECT_EQ(j.str(), "{\n  \"a\\\"b\": \"x<y>&\",\n  \"v\": [1.5, null]\n}");
  EXPECT_EQ(report::escape("<a href='x'>&</a>"), "&lt;a href=&#39;x&#39;&gt;&amp;&lt;/a&gt;");
}

}  // namespace
}  // namespace arthrosim::pipelines
