// The post report's biphasic contact-pressure comparison
// (post_report::biphasic_section): the plot's series and the key-frame table
// are the files' values (largest over the articular vertices per step for the
// biphasic layers, /contact/tibiofemoral/max_pressure for stage 1).
#include <gtest/gtest.h>

#include <filesystem>
#include <variant>

#include "common/hdf5.h"
#include "pipelines/post_report.h"

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
      listed = listed || t->paragraph.find("stage 1 elastic-foundation pressure: no kinematics file") != std::string::npos;
  EXPECT_TRUE(listed);
}

}  // namespace
}  // namespace arthrosim::pipelines::post_report
