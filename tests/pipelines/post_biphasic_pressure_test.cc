// The post report's biphasic contact-pressure comparison
// (post_report::biphasic_section): the plot's series and the key-frame table
// are the files' values (largest over the articular vertices per step for the
// biphasic layers, /contact/tibiofemoral/max_pressure for stage 1, largest
// contact_pressure over every surface's nodes per frame on the trial clock
// for the shell stage), and the section draws in headless Chromium.
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <variant>

#include "common/effects.h"
#include "common/hdf5.h"
#include "common/metadata.h"
#include "pipelines/post_report.h"
#include "pipelines/report_html.h"
#include "pipelines/surface_output.h"
#include "tests/pipelines/chromium_check.h"

namespace arthrosim::pipelines::post_report {
namespace {

namespace fs = std::filesystem;

// A biphasic output holding what biphasic::read_layer_series reads: one layer
// "medial", 3 steps, 4 articular vertices with known stresses.
void write_biphasic(const std::string& path, const Eigen::MatrixXd& sigma, const Eigen::MatrixXd& p) {
  common::H5File f(path, common::H5File::Mode::kTruncate);
  f.write("/time", std::vector<double>{0.10, 0.20, 0.30});
  f.create_group("/regions");
  f.write("/regions/names", std::vector<std::string>{"central", "anterior", "posterior", "medial", "lateral"});
  f.create_group("/layers");
  f.write("/layers/names", std::vector<std::string>{"medial"});
  const std::string g = "/layers/medial";
  f.create_group(g);
  f.create_group(g + "/series");
  f.create_group(g + "/surface");
  for (const char* s : {"contact_area", "fluid_load_support", "max_tensile_stress", "max_shear_stress"})
    f.write(g + "/series/" + s, std::vector<double>{1.0, 2.0, 3.0});
  for (const char* s : {"max_tensile_region", "max_shear_region", "max_tensile_vertex", "max_shear_vertex"})
    f.write(g + "/series/" + s, std::vector<int>{0, 1, 2});
  f.write(g + "/surface/total_normal_stress", sigma);
  f.write(g + "/surface/fluid_pressure", p);
  Eigen::MatrixXd v(sigma.cols(), 3);
  for (Eigen::Index i = 0; i < v.rows(); ++i) v.row(i) << 0.001 * i, 0.5, -0.002 * i;  // [m]
  f.write(g + "/articular_vertices", v);
  for (const char* a : {"factorizations", "solves", "unknowns"}) f.set_attribute(g, a, 1);
  for (const char* a : {"factorization_s", "solve_s"}) f.set_attribute(g, a, 0.5);
}

const report_html::LinePlot* plot(const report_html::Section& s, const std::string& id) {
  for (const auto& b : s.blocks)
    if (const auto* p = std::get_if<report_html::LinePlot>(&b); p && p->id == id) return p;
  return nullptr;
}
const report_html::Table* table(const report_html::Section& s, const std::string& id) {
  for (const auto& b : s.blocks)
    if (const auto* t = std::get_if<report_html::Table>(&b); t && t->id == id) return t;
  return nullptr;
}

TEST(PostBiphasicPressure, SeriesAndKeyFramesAreTheFilesValues) {
  const fs::path dir = fs::path(::testing::TempDir()) / "post_biphasic_pressure";
  fs::create_directories(dir);
  Eigen::MatrixXd sigma(3, 4), p(3, 4);
  sigma << 0.0, 1e6, 3e6, 2e6,  //
      5e6, 4e6, 0.0, 1e6,        //
      0.5e6, 0.2e6, 0.7e6, 0.1e6;
  p = 0.9 * sigma;
  p(1, 1) = 4.6e6;  // the largest p need not be at the vertex of the largest sigma
  write_biphasic((dir / "biphasic.h5").string(), sigma, p);
  {
    common::H5File k((dir / "kinematics.h5").string(), common::H5File::Mode::kTruncate);
    k.write("/time", std::vector<double>{0.10, 0.15, 0.20, 0.25, 0.30});
    k.create_group("/contact");
    k.create_group("/contact/tibiofemoral");
    k.write("/contact/tibiofemoral/max_pressure", std::vector<double>{6e6, 7e6, 8e6, 9e6, 10e6});
  }
  const report_html::Section sec = biphasic_section({{"run", (dir / "biphasic.h5").string()}},
                                                    (dir / "kinematics.h5").string(),
                                                    {{"first peak", 0.19}, {"second peak", 0.29}});
  const auto* pp = plot(sec, "fig-biphasic-pressure");
  ASSERT_NE(pp, nullptr);
  ASSERT_EQ(pp->lines.size(), 3u);
  EXPECT_EQ(pp->lines[0].label, "biphasic medial: total normal stress");
  EXPECT_EQ(pp->lines[0].y, (std::vector<double>{3.0, 5.0, 0.7}));  // row maxima [MPa]
  EXPECT_EQ(pp->lines[1].label, "biphasic medial: fluid pressure");
  ASSERT_EQ(pp->lines[1].y.size(), 3u);
  EXPECT_DOUBLE_EQ(pp->lines[1].y[1], 4.6);
  EXPECT_DOUBLE_EQ(pp->lines[1].y[0], 0.9 * 3.0);
  EXPECT_EQ(pp->lines[2].label, "stage 1 elastic foundation (tibiofemoral)");
  EXPECT_EQ(pp->lines[2].y, (std::vector<double>{6.0, 7.0, 8.0, 9.0, 10.0}));

  const auto* kt = table(sec, "tab-biphasic-pressure");
  ASSERT_NE(kt, nullptr);
  ASSERT_EQ(kt->rows.size(), 3u);
  auto d = [](const report_html::Cell& c) { return std::get<double>(c); };
  // Biphasic steps nearest 0.19 / 0.29 s: 0.20 / 0.30 s.
  EXPECT_DOUBLE_EQ(d(kt->rows[0][1]), 5.0);
  EXPECT_DOUBLE_EQ(d(kt->rows[0][2]), 0.20);
  EXPECT_DOUBLE_EQ(d(kt->rows[0][3]), 0.7);
  EXPECT_DOUBLE_EQ(d(kt->rows[0][4]), 0.30);
  // Stage-1 frames nearest: 0.20 / 0.30 s.
  EXPECT_DOUBLE_EQ(d(kt->rows[2][1]), 8.0);
  EXPECT_DOUBLE_EQ(d(kt->rows[2][3]), 10.0);

  // One map per layer and key frame: the vertices (X, Z in mm) coloured by
  // sigma_Tot_nn at the nearest step [MPa], one colour range over the key frames.
  std::vector<const report_html::MapPlot*> maps;
  for (const auto& b : sec.blocks)
    if (const auto* m = std::get_if<report_html::MapPlot>(&b)) maps.push_back(m);
  ASSERT_EQ(maps.size(), 2u);
  ASSERT_EQ(maps[0]->points.size(), 1u);
  const auto& pts = maps[0]->points[0];
  ASSERT_EQ(pts.values.size(), 4);
  for (int i = 0; i < 4; ++i) {
    EXPECT_DOUBLE_EQ(pts.values[i], 1e-6 * sigma(1, i));
    EXPECT_DOUBLE_EQ(pts.xy(i, 0), 1.0 * i);
    EXPECT_DOUBLE_EQ(pts.xy(i, 1), -2.0 * i);
  }
  EXPECT_DOUBLE_EQ(maps[1]->points[0].values[2], 0.7);
  EXPECT_DOUBLE_EQ(pts.hi, 5.0);
}

// A surface-stage output written by its one writer: surfaces "femur" and
// "tibia" (4 nodes, one quad each), frames on the trial clock `trial_t`
// (the first a seating-ramp frame, before the trial's first frame), contact pressure
// per surface and frame (rows) and node (columns) [Pa]. `contact` false: a
// run without contact (no contact_pressure); `trial` false: no /trial_time.
void write_surface(const std::string& path, const std::vector<double>& trial_t, const Eigen::MatrixXd& p_femur,
                   const Eigen::MatrixXd& p_tibia, bool contact = true, bool trial = true) {
  surface_output::Layout layout;
  layout.scenario = "gait";
  layout.mode = "hht";
  layout.frames_expected = static_cast<std::int64_t>(trial_t.size());
  layout.contact = contact;
  layout.trial_time = trial;
  surface_output::Writer w(path, common::RunMetadata{}, layout, common::EffectLedger("surface:test"));
  for (const char* name : {"femur", "tibia"}) {
    surface_output::SurfaceGeometry g;
    g.name = name;
    g.nodes.resize(4, 3);
    g.nodes << 0, 0, 0, 0.01, 0, 0, 0.01, 0, 0.01, 0, 0, 0.01;
    g.quads.resize(1, 4);
    g.quads << 0, 1, 2, 3;
    g.normals = common::Points3::Zero(4, 3);
    g.normals.col(1).setOnes();
    g.basis_a1 = common::Points3::Zero(4, 3);
    g.basis_a1.col(0).setOnes();
    g.basis_a2 = common::Points3::Zero(4, 3);
    g.basis_a2.col(2).setOnes();
    g.fixed.assign(4, 0);
    w.add_surface(g);
  }
  w.flush();
  for (std::size_t i = 0; i < trial_t.size(); ++i) {
    std::vector<surface_output::SurfaceFrame> frames(2);
    for (int k = 0; k < 2; ++k) {
      auto& f = frames[static_cast<std::size_t>(k)];
      f.displacement = Eigen::MatrixXd::Zero(4, 3);
      f.deflection = Eigen::VectorXd::Zero(4);
      f.E = Eigen::MatrixXd::Zero(4, 3);
      f.e1 = f.e2 = Eigen::VectorXd::Zero(4);
      f.e1_dir = Eigen::MatrixXd::Zero(4, 3);
      f.e1_dir.col(0).setOnes();
      if (contact) f.contact_pressure = (k == 0 ? p_femur : p_tibia).row(static_cast<Eigen::Index>(i)).transpose();
    }
    const surface_output::ContactFrame c;
    w.append_frame(0.01 * static_cast<double>(i), trial_t[i], frames, contact ? &c : nullptr);
  }
  w.complete();
}

// The shell stage's contact pressure joins the comparison: per stored frame
// the largest over both surfaces' nodes, on /trial_time; the key-frame table
// gives the frame nearest each key time and that frame's time; the section
// (with the biphasic and stage-1 sources) draws in headless Chromium.
TEST(PostBiphasicPressure, ShellStageContactPressureAtTheNearestStoredFrames) {
  const fs::path dir = fs::path(::testing::TempDir()) / "post_biphasic_pressure_shell";
  fs::create_directories(dir);
  Eigen::MatrixXd sigma(3, 4);
  sigma << 0.0, 1e6, 3e6, 2e6, 5e6, 4e6, 0.0, 1e6, 0.5e6, 0.2e6, 0.7e6, 0.1e6;
  write_biphasic((dir / "biphasic.h5").string(), sigma, 0.9 * sigma);
  // Frames: seating (trial 0.09 s), then 0.10, 0.16, 0.22, 0.31 s.
  const std::vector<double> tt{0.09, 0.10, 0.16, 0.22, 0.31};
  Eigen::MatrixXd pf(5, 4), pt(5, 4);
  pf << 0, 0, 0, 0,  //
      1e6, 2e6, 0, 0,  //
      3e6, 0, 0, 6e6,  //
      0, 0, 0, 0,      //
      0, 2.5e6, 0, 0;
  pt << 0, 0, 0, 0,  //
      0, 0, 2.5e6, 0,  //
      0, 5.5e6, 0, 0,  //
      0, 0, 7e6, 1e6,  //
      0, 0, 0, 3e6;
  write_surface((dir / "surface_gait.h5").string(), tt, pf, pt);
  // A run without contact and one without the trial clock are named, not drawn.
  write_surface((dir / "surface_free.h5").string(), tt, pf, pt, /*contact=*/false);
  write_surface((dir / "surface_clock.h5").string(), tt, pf, pt, true, /*trial=*/false);

  const report_html::Section sec =
      biphasic_section({{"run", (dir / "biphasic.h5").string()}}, {}, {{"first peak", 0.21}, {"second peak", 0.29}, {"late", 0.36}, {"after", 0.60}},
                       {{"gait", (dir / "surface_gait.h5").string()},
                        {"free", (dir / "surface_free.h5").string()},
                        {"clock", (dir / "surface_clock.h5").string()}});
  const auto* pp = plot(sec, "fig-biphasic-pressure");
  ASSERT_NE(pp, nullptr);
  ASSERT_EQ(pp->lines.size(), 3u);  // biphasic sigma and p, shell gait
  const auto& shell = pp->lines[2];
  EXPECT_EQ(shell.label, "shell stage gait: contact pressure");
  EXPECT_EQ(shell.x, tt);
  EXPECT_EQ(shell.y, (std::vector<double>{0.0, 2.5, 6.0, 7.0, 3.0}));  // max over both surfaces [MPa]

  const auto* kt = table(sec, "tab-biphasic-pressure");
  ASSERT_NE(kt, nullptr);
  ASSERT_EQ(kt->rows.size(), 3u);
  auto d = [](const report_html::Cell& c) { return std::get<double>(c); };
  EXPECT_EQ(std::get<std::string>(kt->rows[2][0]), "shell stage gait: contact pressure");
  // Nearest stored frames: 0.21 s -> 0.22 s (7 MPa), 0.29 s -> 0.31 s (3 MPa).
  EXPECT_DOUBLE_EQ(d(kt->rows[2][1]), 7.0);
  EXPECT_DOUBLE_EQ(d(kt->rows[2][2]), 0.22);
  EXPECT_DOUBLE_EQ(d(kt->rows[2][3]), 3.0);
  EXPECT_DOUBLE_EQ(d(kt->rows[2][4]), 0.31);
  // 0.36 s: 0.05 s after the shell run's last frame (largest spacing 0.09 s)
  // -> 0.31 s; 0.06 s after the biphasic run's last step (spacing 0.10 s) ->
  // 0.30 s. 0.60 s is farther from both than their spacing: no value (NaN,
  // drawn "-").
  EXPECT_DOUBLE_EQ(d(kt->rows[2][6]), 0.31);
  EXPECT_DOUBLE_EQ(d(kt->rows[0][6]), 0.30);
  for (std::size_t r = 0; r < kt->rows.size(); ++r) {
    EXPECT_TRUE(std::isnan(d(kt->rows[r][7]))) << r;
    EXPECT_TRUE(std::isnan(d(kt->rows[r][8]))) << r;
  }

  std::string text;
  for (const auto& b : sec.blocks)
    if (const auto* t = std::get_if<report_html::Text>(&b)) text += t->paragraph;
  EXPECT_NE(text.find("shell stage free: no surface of"), std::string::npos) << text;
  EXPECT_NE(text.find("surface_clock.h5 has no /trial_time"), std::string::npos) << text;
  EXPECT_EQ(text.find("shell stage contact pressure: no surface-stage file"), std::string::npos);

  // Drawn in a real browser (the page's own check after Plotly.newPlot of
  // every figure: the pressure plot, the four series plots, one map per key frame).
  const std::string chromium = arthrosim::testing::chromium_path();
  if (chromium.empty()) GTEST_SKIP() << arthrosim::testing::kNoChromium;
  report_html::Report r;
  r.title = "biphasic pressure comparison";
  r.sections.push_back(sec);
  const fs::path page = report_html::write(r, dir / "report");
  const std::string check = arthrosim::testing::render_check(chromium, page);
  EXPECT_EQ(check, "{\"ok\":true,\"figures\":" + std::to_string(report_html::figure_ids(r).size()) +
                       ",\"failed\":[],\"errors\":[]}")
      << "see " << (dir / "report" / "report.chromium.log");
  EXPECT_EQ(report_html::figure_ids(r).size(), 9u);
}

TEST(PostBiphasicPressure, MissingSourcesAreListed) {
  const fs::path dir = fs::path(::testing::TempDir()) / "post_biphasic_pressure_missing";
  fs::create_directories(dir);
  write_biphasic((dir / "biphasic.h5").string(), Eigen::MatrixXd::Ones(3, 2), Eigen::MatrixXd::Ones(3, 2));
  const report_html::Section sec = biphasic_section({{"run", (dir / "biphasic.h5").string()}});
  const auto* pp = plot(sec, "fig-biphasic-pressure");
  ASSERT_NE(pp, nullptr);
  EXPECT_EQ(pp->lines.size(), 2u);  // biphasic only
  EXPECT_EQ(table(sec, "tab-biphasic-pressure"), nullptr);  // no key frames given
  bool listed = false;
  for (const auto& b : sec.blocks)
    if (const auto* t = std::get_if<report_html::Text>(&b))
      listed = listed || (t->paragraph.find("stage 1 elastic-foundation pressure: no kinematics file") !=
                              std::string::npos &&
                          t->paragraph.find("shell stage contact pressure: no surface-stage file") != std::string::npos);
  EXPECT_TRUE(listed);
}

}  // namespace
}  // namespace arthrosim::pipelines::post_report
