// `arthrosim study accuracy` (pipelines/study.h, docs/studies.md): the series
// comparison against closed forms, the seed-001 recommendation rule and the
// Pareto front on synthetic tables, the metric readers on synthetic stage
// outputs with known errors, and a real study (the cantilever plate of
// data/scenes/cantilever_plate.yaml at four shell resolutions, surface stage
// only, about a second) through the runner and the `arthrosim` executable:
// errors vanish at the reference, the rule picks the expected resolution,
// unchanged stages are reused, the JSON/CSV/HTML are written and parse, and
// bad keys/values stop with clear messages and exit status 1.
#include "pipelines/stages.h"
#include "pipelines/study.h"

#include <gtest/gtest.h>
#include <sys/wait.h>

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <sstream>

#include "common/error.h"
#include "common/hdf5.h"
#include "common/scene.h"
#include "common/scene_edit.h"

namespace arthrosim::pipelines::study {
namespace {
namespace fs = std::filesystem;

const fs::path kDir = fs::path(ARTHROSIM_BINARY_DIR) / "test_scratch" / "study_test";
const fs::path kBin = fs::path(ARTHROSIM_BINARY_DIR) / "bin";

std::string slurp(const fs::path& p) {
  std::ifstream in(p);
  std::stringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

// Runs a shell command; returns (exit status, stdout + stderr).
std::pair<int, std::string> run(const std::string& command) {
  const fs::path out = kDir / "command_output.txt";
  fs::create_directories(kDir);
  const int status = std::system((command + " > " + out.string() + " 2>&1").c_str());
  return {WIFEXITED(status) ? WEXITSTATUS(status) : -1, slurp(out)};
}

// ---------------------------------------------------------------------------
// Series comparison
// ---------------------------------------------------------------------------

// F(t) = a + b t is linear, so linear interpolation of a scaled copy sampled
// at other times is exact: x = (1 + eps) F gives |x - F| = eps |F| at every
// reference time, hence rms / mean|F| = eps exactly when |F| is constant...
// and in general rms = eps sqrt(mean |F|^2). Checked to round-off.
TEST(StudySeries, InterpolatesLinearSeriesExactly) {
  const Eigen::Vector3d a(100, -2000, 30), b(50, 400, -10);
  TimeSeries ref, x;
  ref.t = Eigen::VectorXd::LinSpaced(11, 0.0, 1.0);
  ref.x.resize(11, 3);
  for (int k = 0; k < 11; ++k) ref.x.row(k) = (a + b * ref.t(k)).transpose();
  const double eps = 0.03;
  x.t = Eigen::VectorXd::LinSpaced(7, 0.0, 1.0);  // other frame count
  x.x.resize(7, 3);
  for (int k = 0; k < 7; ++k) x.x.row(k) = ((1 + eps) * (a + b * x.t(k))).transpose();
  const SeriesDifference d = compare_series(x, ref);
  EXPECT_EQ(d.compared, 11);
  EXPECT_EQ(d.skipped, 0);
  double sum_sq = 0, sum_norm = 0;
  for (int k = 0; k < 11; ++k) {
    sum_sq += ref.x.row(k).squaredNorm();
    sum_norm += ref.x.row(k).norm();
  }
  EXPECT_NEAR(d.rms, eps * std::sqrt(sum_sq / 11), 1e-9);
  EXPECT_NEAR(d.mean_norm_ref, sum_norm / 11, 1e-9);
  EXPECT_NEAR(d.rms_per_component, d.rms / std::sqrt(3.0), 1e-12);
  // Against itself: zero.
  const SeriesDifference self = compare_series(ref, ref);
  EXPECT_EQ(self.rms, 0.0);
}

TEST(StudySeries, LeavesOutFailedFramesAndTimesOutsideTheSpan) {
  TimeSeries ref, x;
  ref.t = Eigen::VectorXd::LinSpaced(5, 0.0, 1.0);  // 0, .25, .5, .75, 1
  ref.x = Eigen::MatrixXd::Ones(5, 1);
  ref.valid = {true, false, true, true, true};       // frame 1 failed in the reference
  x.t = Eigen::Vector3d(0.0, 0.5, 0.8);               // ends before t = 1
  x.x = Eigen::MatrixXd::Ones(3, 1) * 2.0;
  x.valid = {true, true, false};                      // 0.5..0.8 unusable
  const SeriesDifference d = compare_series(x, ref);
  // t = 0 and 0.5 compared; 0.25 failed in ref; 0.75 between a valid and a
  // failed sample; 1.0 outside x's span.
  EXPECT_EQ(d.compared, 2);
  EXPECT_EQ(d.skipped, 3);
  EXPECT_DOUBLE_EQ(d.rms, 1.0);
}

// ---------------------------------------------------------------------------
// The seed-001 rule and the Pareto front on synthetic tables
// ---------------------------------------------------------------------------
TEST(StudyRule, PicksCoarsestSettingFromWhichRefiningChangesLessThanFivePercent) {
  const std::vector<std::vector<std::size_t>> g = {{0}, {1}, {2}, {3}, {4}};
  const std::vector<double> cost = {1, 2, 4, 8, 16};
  // 7 % at index 2 blocks index 1 (4 %) although index 1 alone is within.
  EXPECT_EQ(recommend_setting(g, {0.2, 0.04, 0.07, 0.01, 0.0}, cost, 0.05), 3);
  EXPECT_EQ(recommend_setting(g, {0.2, 0.04, 0.03, 0.01, 0.0}, cost, 0.05), 1);
  EXPECT_EQ(recommend_setting(g, {0.05, 0.04, 0.03, 0.01, 0.0}, cost, 0.05), 0);  // 5 % is "no more than"
  EXPECT_EQ(recommend_setting(g, {0.2, 0.1, 0.08, 0.06, 0.0}, cost, 0.05), 4);    // only the reference
  // Unknown error (failed run) at a finer setting: nothing coarser qualifies.
  const double nan = std::numeric_limits<double>::quiet_NaN();
  EXPECT_EQ(recommend_setting(g, {0.01, 0.01, nan, 0.01, 0.0}, cost, 0.05), 3);
  EXPECT_EQ(recommend_setting(g, {nan, nan, nan, nan, nan}, cost, 0.05), -1);
}

// Coarser is not always cheaper (the gait scene's Newton increment floor:
// 0.03 mm took 813 s, 0.01 mm 523 s, 0.001 mm 696 s, all within 0.4 %,
// docs/studies.md): the rule still names the coarsest qualifying setting,
// the cheapest qualifying one is reported beside it.
TEST(StudyRule, CheapestQualifyingSettingNeedNotBeTheCoarsest) {
  const std::vector<std::vector<std::size_t>> g = {{0}, {1}, {2}};
  const std::vector<double> err = {0.0031, 0.0025, 0.0};
  EXPECT_EQ(recommend_setting(g, err, {813, 523, 696}, 0.05), 0);
  EXPECT_EQ(cheapest_qualifying_setting(g, err, {813, 523, 696}, 0.05), 1);
  EXPECT_EQ(cheapest_qualifying_setting(g, err, {100, 523, 696}, 0.05), 0);
  // A setting that does not qualify is never the cheapest qualifying one.
  EXPECT_EQ(cheapest_qualifying_setting(g, {0.0031, 0.07, 0.0}, {813, 523, 696}, 0.05), 2);
  const double nan = std::numeric_limits<double>::quiet_NaN();
  EXPECT_EQ(cheapest_qualifying_setting(g, {nan, nan, nan}, {1, 2, 3}, 0.05), -1);
}

TEST(StudyRule, GridPicksTheCheapestOfTheCoarsestQualifyingSettings) {
  // Two axes of three values; each axis adds 10 %, 3 %, 0 % at value 0, 1, 2.
  const double e[3] = {0.10, 0.03, 0.0};
  std::vector<std::vector<std::size_t>> g;
  std::vector<double> err, cost;
  for (std::size_t i = 0; i < 3; ++i) {
    for (std::size_t j = 0; j < 3; ++j) {
      g.push_back({i, j});
      err.push_back(e[i] + e[j]);
      cost.push_back(1.0 + 3.0 * i + 1.0 * j);  // axis 0 is the expensive one
    }
  }
  // (1,1) is 6 %: out. (1,2) and (2,1) are 3 % with only 0-3 % settings finer:
  // both qualify and neither is coarser than the other; (1,2) costs 6, (2,1) 8.
  const int r = recommend_setting(g, err, cost, 0.05);
  ASSERT_GE(r, 0);
  EXPECT_EQ(g[static_cast<std::size_t>(r)], (std::vector<std::size_t>{1, 2}));
  // Make axis 1 the expensive one: (2,1) wins.
  for (std::size_t s = 0; s < g.size(); ++s) cost[s] = 1.0 + g[s][0] + 3.0 * g[s][1];
  EXPECT_EQ(g[static_cast<std::size_t>(recommend_setting(g, err, cost, 0.05))], (std::vector<std::size_t>{2, 1}));
}

TEST(StudyRule, ParetoFrontKeepsOnlyUndominatedPoints) {
  const std::vector<double> t = {1, 2, 3, 4, 2.5};
  const std::vector<double> e = {0.5, 0.1, 0.2, 0.01, 0.1};
  // 3 (t=3, e=0.2) is dominated by 1 (t=2, e=0.1); 4 (t=2.5, e=0.1) by 1.
  EXPECT_EQ(pareto_front(t, e), (std::vector<int>{0, 1, 3}));
}

// ---------------------------------------------------------------------------
// Metric readers on synthetic stage outputs
// ---------------------------------------------------------------------------
void write_kinematics(const fs::path& file, int frames, double force_scale, double activation_shift,
                      int failed_frame) {
  common::H5File f(file.string(), common::H5File::Mode::kTruncate);
  f.set_attribute("/", "format", "arthrosim kinematics file");  // what the reader checks (common/file_check.h)
  f.set_attribute("/", "format_version", 1);
  f.set_attribute("/", "frames", frames);  // the run summary of a finished run (the study refuses unfinished ones)
  Eigen::VectorXd t = Eigen::VectorXd::LinSpaced(frames, 0.0, 1.0);
  Eigen::MatrixXd force(frames, 3), act(frames, 2);
  Eigen::VectorXi status = Eigen::VectorXi::Zero(frames);
  for (int k = 0; k < frames; ++k) {
    force.row(k) = force_scale * Eigen::RowVector3d(100 * t(k), -1000 - 500 * t(k), 20);
    act.row(k) = Eigen::RowVector2d(0.2 + 0.3 * t(k) + activation_shift, 0.1 + activation_shift);
  }
  if (failed_frame >= 0) {
    status(failed_frame) = 1;
    force.row(failed_frame) *= 50.0;  // garbage in a failed frame must not count
  }
  f.write("/time", t);
  f.write("/contact/tibiofemoral/force", force);
  f.write("/muscles/activation", act);
  f.write("/muscles/names", std::vector<std::string>{"vasti", "hamstrings"});
  f.write("/solver/status", status);
}

TEST(StudyMetrics, ComakErrorsOfKnownSize) {
  fs::create_directories(kDir);
  write_kinematics(kDir / "k_ref.h5", 21, 1.0, 0.0, -1);
  write_kinematics(kDir / "k_a.h5", 11, 1.02, 0.01, 5);
  const std::vector<Metric> m = comak_metrics(kDir / "k_a.h5", kDir / "k_ref.h5");
  ASSERT_EQ(m.size(), 2u);
  EXPECT_EQ(m[0].name, "contact_force");
  // Force scaled by 1.02 and linear in t: |F - F_ref| = 0.02 |F_ref| at every
  // compared frame, so rms/mean = 0.02 sqrt(mean |F|^2) / mean |F|, which is
  // 0.02 to within the variation of |F| (1000..1500 N): below 1 % of 0.02.
  EXPECT_NEAR(m[0].error, 0.02, 0.02 * 0.01);
  EXPECT_EQ(m[1].name, "activations");
  EXPECT_NEAR(m[1].error, 0.01, 1e-12);  // constant shift of 0.01, exact
  // The failed frame (t = 0.5) and the reference frames next to it are left out.
  EXPECT_NE(m[0].note.find("left out"), std::string::npos) << m[0].note;
  const std::vector<Metric> self = comak_metrics(kDir / "k_ref.h5", kDir / "k_ref.h5");
  EXPECT_EQ(self[0].error, 0.0);
  EXPECT_EQ(self[1].error, 0.0);
}

void write_surface(const fs::path& file, int frames, int nodes, double peak_m, bool contact) {
  common::H5File f(file.string(), common::H5File::Mode::kTruncate);
  f.write("/time", Eigen::VectorXd(Eigen::VectorXd::LinSpaced(frames, 0.0, 1.0)));
  Eigen::MatrixXd d = Eigen::MatrixXd::Zero(frames, nodes);
  d(frames / 2, nodes / 3) = peak_m;  // the largest magnitude, signed
  d(frames - 1, 0) = 0.5 * std::abs(peak_m);
  f.write("/surfaces/femur/deflection", d);
  if (contact) {
    Eigen::MatrixXd force = Eigen::MatrixXd::Zero(frames, 3);
    force.col(1).setConstant(-700.0 * (peak_m > 0 ? 1.0 : 1.1));
    f.write("/contact/tibiofemoral/force", force);
  }
}

TEST(StudyMetrics, SurfaceComparesPeakDeflectionAcrossResolutionsAndContactWhenPresent) {
  fs::create_directories(kDir);
  write_surface(kDir / "s_ref.h5", 9, 400, 1.2e-3, false);
  write_surface(kDir / "s_a.h5", 5, 100, 1.14e-3, false);  // other mesh, other frames
  std::vector<Metric> m = surface_metrics(kDir / "s_a.h5", kDir / "s_ref.h5");
  ASSERT_EQ(m.size(), 2u);
  EXPECT_EQ(m[0].name, "max_deflection[femur]");
  EXPECT_NEAR(m[0].error, 0.05, 1e-12);
  EXPECT_NEAR(m[0].output, 1.14, 1e-12);  // mm
  EXPECT_EQ(m[1].name, "contact_force");
  EXPECT_TRUE(std::isnan(m[1].error));  // absent: said so, not zero
  EXPECT_NE(m[1].note.find("/contact/tibiofemoral/force absent"), std::string::npos) << m[1].note;
  // With contact forces in both files: 700 vs 770 N -> 10 %.
  write_surface(kDir / "s_ref_c.h5", 9, 400, 1.2e-3, true);
  write_surface(kDir / "s_b_c.h5", 5, 100, -1.2e-3, true);
  m = surface_metrics(kDir / "s_b_c.h5", kDir / "s_ref_c.h5");
  EXPECT_NEAR(m[0].error, 2.0, 1e-12);  // opposite sign: |-d - d| / |d|
  EXPECT_NEAR(m[1].error, 0.1, 1e-12);
}

TEST(StudyMetrics, PostMeanAngleFromSummary) {
  fs::create_directories(kDir);
  std::ofstream(kDir / "sum_ref.json") << R"({"schema": "arthrosim post summary 1", "scenarios": [
    {"scenario": "osmotic", "angle_statistics": [{"region": "all", "samples": 10, "covered": 8,
      "mean_deg": 20.0, "median_deg": 18}]}]})";
  std::ofstream(kDir / "sum_a.json") << R"({"scenarios": [{"scenario": "osmotic", "angle_statistics": [
    {"region": "medial", "covered": 1, "mean_deg": 20.0}, {"region": "lateral", "covered": 3,
     "mean_deg": 24.0}]}], "note": "escapes \" \\ \u00e9"})";
  std::vector<Metric> m = post_metrics(kDir / "sum_a.json", kDir / "sum_ref.json");
  ASSERT_EQ(m.size(), 1u);
  EXPECT_EQ(m[0].name, "mean_angle[osmotic]");
  EXPECT_NEAR(m[0].output, 23.0, 1e-12);  // covered-weighted (1 x 20 + 3 x 24) / 4
  EXPECT_NEAR(m[0].error, 0.15, 1e-12);
  // No map: no angle statistics -> not available, with the reason.
  std::ofstream(kDir / "sum_nomap.json") << R"({"scenarios": [{"scenario": "osmotic"}]})";
  m = post_metrics(kDir / "sum_nomap.json", kDir / "sum_nomap.json");
  EXPECT_TRUE(std::isnan(m[0].error));
  EXPECT_NE(m[0].note.find("splitline_map"), std::string::npos);
  std::ofstream(kDir / "sum_bad.json") << R"({"scenarios": [)";
  EXPECT_THROW(post_metrics(kDir / "sum_bad.json", kDir / "sum_ref.json"), common::InputError);
}

// ---------------------------------------------------------------------------
// A real study: the cantilever plate at 2, 4, 8, 16 quads along its length
// ---------------------------------------------------------------------------

// Plate 100 x 10 mm in z = 0, n x 1 quads (the layout of the bundled
// cantilever_plate.obj, which is n = 16).
void write_plate(const fs::path& file, int n) {
  std::ofstream f(file);
  f << "# cantilever plate 100 x 10 mm, " << n << " x 1 quads\n";
  for (int row = 0; row < 2; ++row) {
    for (int i = 0; i <= n; ++i) f << "v " << 100.0 * i / n << " " << 10.0 * row << " 0\n";
  }
  for (int i = 0; i < n; ++i) f << "f " << i + 1 << " " << i + 2 << " " << n + 1 + i + 2 << " " << n + 1 + i + 1 << "\n";
}

fs::path write_cantilever_study_scene(const fs::path& dir) {
  fs::create_directories(dir);
  for (int n : {2, 4, 8, 16}) write_plate(dir / ("plate" + std::to_string(n) + ".obj"), n);
  std::string text = slurp(fs::path(ARTHROSIM_SOURCE_DIR) / "data/scenes/cantilever_plate.yaml");
  // Same scene, its mesh and model named relative to the new folder (the
  // study must resolve them against the scene file, not the working folder).
  const std::string from = "mesh: cantilever_plate.obj";
  text.replace(text.find(from), from.size(), "mesh: plate16.obj");
  const std::string model = "model: ../models/knee_parametric/coarse";
  text.replace(text.find(model), model.size(),
               "model: " + fs::relative(fs::path(ARTHROSIM_SOURCE_DIR) / "data/models/knee_parametric/coarse", dir).string());
  std::ofstream(dir / "plate.yaml") << text;
  return dir / "plate.yaml";
}

class StudyRun : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    fs::remove_all(kDir / "cantilever");
    scene_ = write_cantilever_study_scene(kDir / "cantilever" / "scene");
  }
  static StudyOptions options(const fs::path& out) {
    StudyOptions o;
    o.scene_file = scene_;
    o.axes = {parse_vary("surface.scenarios.cantilever.mesh=plate2.obj,plate4.obj,plate8.obj,plate16.obj")};
    o.out_dir = out;
    o.stage_dir = kBin;
    o.command_line = "study_test";
    return o;
  }
  static fs::path scene_;
};
fs::path StudyRun::scene_;

TEST_F(StudyRun, CantileverResolutionStudyRecommendsFourQuads) {
  const StudyOptions o = options(kDir / "cantilever" / "out");
  std::ostringstream log;
  const StudyResult r = run_accuracy_study(o, log);
  ASSERT_EQ(r.settings.size(), 4u) << log.str();
  EXPECT_EQ(r.reference, 3u);
  std::vector<double> err;
  for (const SettingResult& s : r.settings) {
    ASSERT_TRUE(s.ok) << s.failure << log.str();
    // Stage programs split NAME=FILE arguments (arthrosim-post --surface).
    EXPECT_EQ(s.dir.string().find('='), std::string::npos) << s.dir;
    ASSERT_EQ(s.stages.size(), 2u);
    EXPECT_EQ(s.stages[0].stage, "prepare");
    EXPECT_EQ(s.stages[1].stage, "surface.cantilever");
    EXPECT_EQ(s.stages[1].run, "ran");
    EXPECT_GT(s.stages[1].wall_time_s, 0.0);
    EXPECT_GT(s.stages[1].max_rss_mb, 1.0);  // a real process's peak RSS, not a placeholder
    EXPECT_GE(s.stages[1].time_to_output_s, s.stages[1].wall_time_s + s.stages[0].wall_time_s - 1e-12);
    ASSERT_GE(s.stages[1].metrics.size(), 1u);
    err.push_back(s.stages[1].metrics[0].error);
  }
  // prepare runs once; the other settings reuse its output (copied, hashes checked).
  EXPECT_EQ(r.settings[0].stages[0].run, "ran");
  // prepare has no metric, so no recommendation: only the surface stage has one.
  EXPECT_EQ(r.recommended.size(), 1u);
  for (std::size_t i = 1; i < 4; ++i) {
    EXPECT_EQ(r.settings[i].stages[0].run, "reused");
    EXPECT_EQ(r.settings[i].stages[0].produced_by, r.settings[0].label);
    EXPECT_EQ(r.settings[i].stages[0].wall_time_s, r.settings[0].stages[0].wall_time_s);
  }
  // Errors vanish at the reference and shrink with refinement. Against beam
  // theory the tip errors are 6.25e-2, 1.56e-2, 3.86e-3, 9.3e-4
  // (docs/surface_output.md), so against 16 quads: about 6.2 %, 1.5 %, 0.3 %.
  EXPECT_EQ(err[3], 0.0);
  EXPECT_GT(err[0], 0.05);
  EXPECT_LT(err[1], 0.05);
  EXPECT_GT(err[0], err[1]);
  EXPECT_GT(err[1], err[2]);
  // The second-order element: refining by 2 divides the error by about 4.
  EXPECT_NEAR(std::log2((err[0] + 0.00093) / (err[1] + 0.00093)), 2.0, 0.1);
  ASSERT_EQ(r.recommended.size(), 1u);
  EXPECT_EQ(r.recommended[0].stage, "surface.cantilever");
  EXPECT_EQ(r.recommended[0].setting, 1);  // plate4.obj
  // The contact-force metric is absent from these files and said so.
  bool noted = false;
  for (const std::string& n : r.notes) noted = noted || n.find("contact_force") != std::string::npos;
  EXPECT_TRUE(noted);

  // Outputs parse: JSON, CSV (rows x columns), XHTML with one inline SVG plot.
  write_study_outputs(o, r);
  const fs::path script = kDir / "check_study.py";
  std::ofstream(script) << R"PY(
import csv, json, sys, xml.etree.ElementTree as ET
d = sys.argv[1]
s = json.load(open(d + '/study.json'))
assert s['schema'] == 'arthrosim accuracy study 1'
assert len(s['settings']) == 4
ref = [x for x in s['settings'] if x['reference']]
assert len(ref) == 1 and ref[0]['stages'][1]['stage_error'] == 0
assert s['recommended'][0]['setting'].endswith('plate4.obj'), s['recommended']
rows = list(csv.DictReader(open(d + '/study.csv')))
assert len(rows) == 8, len(rows)
assert sum(1 for r in rows if r['recommended'] == 'yes') == 1
for r in rows:
    float(r['wall_time_s']); float(r['max_rss_mb'])
root = ET.parse(d + '/report.html').getroot()
svgs = list(root.iter('{http://www.w3.org/2000/svg}svg'))
assert len(svgs) == 1
circles = list(svgs[0].iter('{http://www.w3.org/2000/svg}circle'))
assert len(circles) >= 4, len(circles)
assert any('recommended' in ''.join(tr.itertext()) for tr in root.iter('{http://www.w3.org/1999/xhtml}tr'))
print('ok')
)PY";
  const auto [status, out] = run("/usr/bin/python3 " + script.string() + " " + o.out_dir.string());
  EXPECT_EQ(status, 0) << out;
}

TEST_F(StudyRun, SecondRunReusesEveryStageAndKeepsItsMeasuredCost) {
  const StudyOptions o = options(kDir / "cantilever" / "again");
  std::ostringstream log1, log2;
  const StudyResult first = run_accuracy_study(o, log1);
  // A stamp written by another build of the stage program (as after a
  // rebuild) in the second setting's folder: the study replaces it with the
  // first setting's current one instead of rerunning prepare there.
  const fs::path stamp = first.settings[1].dir / ".stamps" / "prepare.txt";
  std::string text = slurp(stamp);
  const std::size_t at = text.find("executable\t");
  ASSERT_NE(at, std::string::npos);
  text.replace(at + 11, 8, "00000000");
  std::ofstream(stamp) << text;
  const StudyResult second = run_accuracy_study(o, log2);
  ASSERT_EQ(second.settings.size(), 4u);
  for (std::size_t i = 0; i < 4; ++i) {
    for (std::size_t k = 0; k < 2; ++k) {
      const StageRecord& a = first.settings[i].stages[k];
      const StageRecord& b = second.settings[i].stages[k];
      EXPECT_EQ(b.run, "reused") << b.stage << log2.str();
      EXPECT_EQ(b.key, a.key);
      EXPECT_EQ(b.wall_time_s, a.wall_time_s);  // from the measurement record
      EXPECT_EQ(b.max_rss_mb, a.max_rss_mb);
    }
    EXPECT_EQ(second.settings[i].stages[1].stage_error, first.settings[i].stages[1].stage_error);
  }
  EXPECT_EQ(second.recommended[0].setting, first.recommended[0].setting);
}

// A stage that fails but writes its output (arthrosim-comak exits 2 when
// frames failed, marking them in the file): compared over what it wrote,
// never recommended. Simulated by a wrapper around the real surface stage that
// exits 2 for the 4-quad plate.
TEST_F(StudyRun, FailedStageWithOutputIsComparedButNeverRecommended) {
  const fs::path bin = kDir / "cantilever" / "wrapped_bin";
  fs::create_directories(bin);
  fs::remove(bin / "arthrosim-prepare");
  fs::create_symlink(kBin / "arthrosim-prepare", bin / "arthrosim-prepare");
  std::ofstream(bin / "arthrosim-surface") << "#!/bin/sh\n" << (kBin / "arthrosim-surface").string()
                                           << " \"$@\" || exit $?\ncase \"$*\" in *plate4.obj*) exit 2;; esac\n";
  fs::permissions(bin / "arthrosim-surface", fs::perms::owner_all);
  StudyOptions o = options(kDir / "cantilever" / "wrapped");
  o.stage_dir = bin;
  std::ostringstream log;
  const StudyResult r = run_accuracy_study(o, log);
  ASSERT_EQ(r.settings.size(), 4u);
  EXPECT_FALSE(r.settings[1].ok);
  const StageRecord& failed = r.settings[1].stages[1];
  EXPECT_EQ(failed.run, "failed");
  EXPECT_EQ(failed.failure, "exited with status 2");
  EXPECT_TRUE(failed.failed_with_output);
  ASSERT_FALSE(failed.metrics.empty());
  EXPECT_LT(failed.metrics[0].error, 0.05);  // the 4-quad plate's own (good) result
  EXPECT_NE(failed.metrics[0].note.find("the stage failed (exited with status 2)"), std::string::npos);
  // Without it plate4 would be recommended; failed, the next finer one is.
  EXPECT_EQ(r.recommended.at(0).setting, 2);
}

// ---------------------------------------------------------------------------
// Bad input through the executable
// ---------------------------------------------------------------------------
class StudyCli : public StudyRun {};

TEST_F(StudyCli, UnknownKeyIsRefusedWithTheKnownKeys) {
  const auto [status, out] = run(
      (kBin / "arthrosim").string() + " study accuracy " + scene_.string() +
      " --vary surface.scenarios.cantilever.youngs_modulus=100,400 --out " + (kDir / "bad").string());
  EXPECT_EQ(status, 1) << out;
  EXPECT_NE(out.find("unknown scene key 'surface.scenarios.cantilever.youngs_modulus'"), std::string::npos) << out;
  EXPECT_NE(out.find("did you mean 'surface.scenarios.cantilever.youngs_modulus_mpa'"), std::string::npos) << out;
  EXPECT_NE(out.find("prepare.edge_length_mm"), std::string::npos) << out;  // the list of keys
  EXPECT_FALSE(fs::exists(kDir / "bad" / "runs")) << "nothing may run on bad input";
  const auto [s2, o2] = run((kBin / "arthrosim").string() + " study accuracy " + scene_.string() +
                            " --vary surface.scenarios.knee.time_step_s=1e-3,1e-4 --out " + (kDir / "bad").string());
  EXPECT_EQ(s2, 1);
  EXPECT_NE(o2.find("no scenario 'knee'; its scenarios: cantilever"), std::string::npos) << o2;
  const auto [s3, o3] = run((kBin / "arthrosim").string() + " study accuracy " + scene_.string() +
                            " --vary surface.scenarios.cantilever.effects=a,b --out " + (kDir / "bad").string());
  EXPECT_EQ(s3, 1);
  EXPECT_NE(o3.find("only single values can be varied"), std::string::npos) << o3;
}

TEST_F(StudyCli, BadValuesAndUselessAxesAreRefusedBeforeAnythingRuns) {
  const std::string base = (kBin / "arthrosim").string() + " study accuracy " + scene_.string() + " --out " +
                           (kDir / "bad").string();
  auto [s1, o1] = run(base + " --vary surface.scenarios.cantilever.youngs_modulus_mpa=400,abc");
  EXPECT_EQ(s1, 1);
  EXPECT_NE(o1.find("--vary surface.scenarios.cantilever.youngs_modulus_mpa=abc"), std::string::npos) << o1;
  EXPECT_NE(o1.find("expected a number, found 'abc'"), std::string::npos) << o1;
  auto [s2, o2] = run(base + " --vary prepare.edge_length_mm=3,100");
  EXPECT_EQ(s2, 1);
  EXPECT_NE(o2.find("expected a value in [0.2, 20]"), std::string::npos) << o2;
  // The scene asks for no report, so no stage reads post options.
  auto [s3, o3] = run(base + " --vary post.outline_points=50,100");
  EXPECT_EQ(s3, 1);
  EXPECT_NE(o3.find("no stage this scene runs reads post.outline_points"), std::string::npos) << o3;
  // 400 and 4e2 mean the same.
  auto [s4, o4] = run(base + " --vary surface.scenarios.cantilever.youngs_modulus_mpa=400,4e2");
  EXPECT_EQ(s4, 1);
  EXPECT_NE(o4.find("the values '400' and '4e2' run every stage with the same options"), std::string::npos) << o4;
  auto [s5, o5] = run(base + " --vary surface.scenarios.cantilever.youngs_modulus_mpa=300,400 --reference 500");
  EXPECT_EQ(s5, 1);
  EXPECT_NE(o5.find("'500' is not one of the values of surface.scenarios.cantilever.youngs_modulus_mpa (300, 400)"),
            std::string::npos) << o5;
  auto [s6, o6] = run(base + " --vary surface.scenarios.cantilever.youngs_modulus_mpa");
  EXPECT_EQ(s6, 1);
  EXPECT_NE(o6.find("expected KEY=V1,V2,..."), std::string::npos) << o6;
  auto [s7, o7] = run(base + " --vary surface.scenarios.cantilever.youngs_modulus_mpa=300,,400");
  EXPECT_EQ(s7, 1);
  EXPECT_NE(o7.find("found an empty value"), std::string::npos) << o7;
  EXPECT_FALSE(fs::exists(kDir / "bad" / "runs"));
}

TEST(StudySceneEdit, CopyNamesTheSameFilesAndCarriesTheSetting) {
  const fs::path scene = write_cantilever_study_scene(kDir / "edit");
  const std::string text = common::edit_scene_text(
      scene, scene_schema(), {{"surface.scenarios.cantilever.mesh", "plate4.obj"}, {"prepare.edge_length_mm", "2.5"}});
  fs::create_directories(kDir / "edit" / "elsewhere" / "deeper");
  const common::Scene copy = parse_scene(text, kDir / "edit" / "elsewhere" / "deeper" / "copy.yaml");
  const common::Scene original = load_scene(scene);
  const common::OptionBlock& cantilever = copy.instances("surface").at(0).options;
  EXPECT_EQ(scene_inputs(copy).model, scene_inputs(original).model);
  EXPECT_EQ(cantilever.path("mesh"), fs::weakly_canonical(kDir / "edit" / "plate4.obj"));
  EXPECT_EQ(copy.block("prepare").as_written("edge_length_mm"), 2.5);  // a block the original did not have
  EXPECT_EQ(cantilever.as_written("youngs_modulus_mpa"), 400.0);  // untouched
  EXPECT_EQ(cantilever.canonical_text(),
            parse_scene(common::edit_scene_text(scene, scene_schema(),
                                                {{"surface.scenarios.cantilever.mesh",
                                                  (kDir / "edit" / "plate4.obj").string()}}),
                        kDir / "copy2.yaml")
                .instances("surface")
                .at(0)
                .options.canonical_text());
}

}  // namespace
}  // namespace arthrosim::pipelines::study
