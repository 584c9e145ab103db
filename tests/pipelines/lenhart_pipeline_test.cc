// Every stage on the real subject (the bundled lenhart2015 knee of
// OpenSim-JAM and its walking trial overground_17), through the scene a user
// runs, data/scenes/lenhart2015_gait.yaml, in a short window: prepare at the
// seed's femoral resolution, COMAK over the first frames of the walk, the
// seed's three surface scenarios (steady osmotic swelling, the walk and the
// walk with osmotic pressure) on the real prepared meshes, and post with its
// report. The whole walk is a script (scripts/lenhart2015_walk.sh, figures in
// docs/surface_output.md "The real subject"), not a test.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>

#include "common/hdf5.h"

namespace common = arthrosim::common;
namespace fs = std::filesystem;

namespace {

const fs::path kRoot = ARTHROSIM_SOURCE_DIR;

std::string work_dir() {
  const fs::path d = fs::path(ARTHROSIM_BINARY_DIR) / "tests" / "lenhart_pipeline_test_scratch";
  fs::create_directories(d);
  return d.string();
}

std::string slurp(const fs::path& p) {
  std::ifstream f(p);
  std::stringstream s;
  s << f.rdbuf();
  return s.str();
}

// Stage 1's force interpolated linearly at time t (rows of F: frames).
double axial_at(const Eigen::VectorXd& t1, const Eigen::MatrixXd& F1, double t) {
  for (Eigen::Index i = 0; i + 1 < t1.size(); ++i)
    if (t >= t1(i) - 1e-12 && t <= t1(i + 1) + 1e-12) {
      const double w = (t - t1(i)) / (t1(i + 1) - t1(i));
      return -((1 - w) * F1(i, 1) + w * F1(i + 1, 1));
    }
  return std::nan("");
}

// Largest value of the report summary's contact-force series `label`
// (summary.json: {"label": L, "time_s": [...], "value_N": [...]}); NaN when
// the series is absent.
double series_max(const std::string& summary, const std::string& label) {
  const auto at = summary.find("\"label\": \"" + label + "\"");
  if (at == std::string::npos) return std::nan("");
  const auto v = summary.find("\"value_N\": [", at);
  if (v == std::string::npos) return std::nan("");
  const char* p = summary.c_str() + v + 12;
  double best = -HUGE_VAL;
  while (*p && *p != ']') {
    char* end = nullptr;
    const double x = std::strtod(p, &end);
    if (end == p) break;
    best = std::max(best, x);
    p = end;
    while (*p == ',' || *p == ' ') ++p;
  }
  return best;
}

}  // namespace

// The scene's every stage, 3 stage-1 frames (1.21-1.23 s, right heel strike)
// and 3 surface steps per walk (2 seating steps + 1). About 230 s, most of it
// the walk's second seating step, where the contact engages at once: 84
// Newton iterations over 3 augmentations, 130-150 s (a 0.04-s seating over
// 4 steps takes 93 iterations, so a longer ramp does not help).
TEST(RealSubjectPipeline, EveryStageRunsOnTheRealKneeInAShortWindow) {
  const std::string out = work_dir() + "/run";
  fs::remove_all(out);
  const std::string exe = std::string(ARTHROSIM_BINARY_DIR) + "/bin/arthrosim";
  ASSERT_TRUE(fs::exists(exe)) << exe << " not built";
  const std::string cmd = exe + " run " + (kRoot / "data/scenes/lenhart2015_gait.yaml").string() + " --out " +
                          out + " --jobs 1 --set trial.end_s=1.23" +
                          " --set surface.scenarios.gait.end_time_s=0.01" +
                          " --set surface.scenarios.gait_osmotic.end_time_s=0.01 > " + out + ".log 2>&1";
  ASSERT_EQ(std::system(cmd.c_str()), 0) << "see " << out << ".log";

  // Prepare at the seed's femoral resolution (about 3,600 shells; 4 mm gives
  // 3,588, docs/prepared_model.md), the tibial cartilage split in two.
  const common::H5File prepared(out + "/prepared.h5", common::H5File::Mode::kRead);
  const Eigen::Index femoral_quads = prepared.read_matrix_int("/surfaces/femur/quads/quads").rows();
  EXPECT_GE(femoral_quads, 3300);
  EXPECT_LE(femoral_quads, 3900);
  EXPECT_GT(prepared.read_matrix_int("/surfaces/tibia_medial/quads/quads").rows(), 500);
  EXPECT_GT(prepared.read_matrix_int("/surfaces/tibia_lateral/quads/quads").rows(), 500);

  const common::H5File kin(out + "/kinematics.h5", common::H5File::Mode::kRead);
  const Eigen::VectorXd t1 = kin.read_vector("/time");
  const Eigen::MatrixXd F1 = kin.read_matrix("/contact/tibiofemoral/force");
  ASSERT_EQ(t1.size(), 3);
  // The one tibial contact surface's force split per compartment (prepare's
  // parts): both loaded, summing to the total (docs/comak.md).
  const Eigen::MatrixXd M1 = kin.read_matrix("/contact/tibiofemoral/medial_force");
  const Eigen::MatrixXd L1 = kin.read_matrix("/contact/tibiofemoral/lateral_force");
  for (Eigen::Index i = 0; i < t1.size(); ++i) {
    EXPECT_GT(M1.row(i).norm(), 0.2 * F1.row(i).norm()) << t1(i);
    EXPECT_GT(L1.row(i).norm(), 0.2 * F1.row(i).norm()) << t1(i);
    EXPECT_LT((M1.row(i) + L1.row(i) - F1.row(i)).norm(), 1e-12 * F1.row(i).norm()) << t1(i);
  }

  for (const char* sc : {"osmotic", "gait", "gait_osmotic"}) {
    const std::string path = out + "/surface_" + sc + ".h5";
    const common::H5File f(path, common::H5File::Mode::kRead);
    EXPECT_EQ(f.attribute_string("/", "status"), "completed") << path;
    const Eigen::MatrixXd defl = f.read_matrix("/surfaces/femur/deflection");
    EXPECT_EQ(defl.cols(), prepared.read_matrix("/surfaces/femur/quads/nodes").rows()) << path;
    EXPECT_TRUE(defl.allFinite()) << path;
    if (std::string(sc) == "osmotic") continue;
    // The stage-2 axial force follows stage 1's at heel strike: measured
    // +17 / +18 % (gait) and +11 / +12 % (gait_osmotic) at 1.21 / 1.22 s
    // with the scene's augmented contact, where the cartilage takes the
    // whole overlap and the 1-mm shells spread the load onto springs
    // outside the contact (docs/contact.md, "Stage 2 against stage 1 on the
    // real subject"). 25 % leaves room for that, and still fails on a lost
    // compartment (about half the force each) or an unloaded walk.
    const Eigen::VectorXd tt = f.read_vector("/trial_time");
    const Eigen::MatrixXd F2 = f.read_matrix("/contact/tibiofemoral/force");
    int compared = 0;
    for (Eigen::Index i = 0; i < tt.size(); ++i) {
      const double a1 = axial_at(t1, F1, tt(i));
      if (std::isnan(a1)) continue;
      ++compared;
      EXPECT_GT(a1, 500.0) << "stage 1 at heel strike, " << tt(i) << " s";
      EXPECT_NEAR(-F2(i, 1) / a1, 1.0, 0.25) << sc << " at " << tt(i) << " s";
    }
    EXPECT_GE(compared, 2) << sc;
    // The seed's accuracy rule is recorded for every step (docs/contact.md).
    const Eigen::VectorXd ratio = f.read_vector("/solver/penetration_ratio");
    const Eigen::VectorXd steps = f.read_vector("/solver/time");
    EXPECT_EQ(ratio.size(), steps.size()) << sc;
    EXPECT_TRUE(ratio.allFinite()) << sc;
    EXPECT_GT(ratio.maxCoeff(), 0.0) << sc << ": no step in contact";
    // The walks' augmented contact (contact_augmentations 8, tolerance
    // 0.08): every step meets the seed's rule, penetration <= 0.1 x
    // deflection (the penalty alone: about 0.18-0.24 at heel strike).
    EXPECT_LE(ratio.maxCoeff(), 0.1) << sc;
    EXPECT_TRUE(f.exists("/solver/contact_augmentations")) << sc;
  }

  // Post: the report with the accuracy rule and the split-line comparison.
  const std::string report = slurp(out + "/report.html");
  EXPECT_NE(report.find("fig-accuracy-rule"), std::string::npos);
  const std::string summary = slurp(out + "/summary.json");
  EXPECT_NE(summary.find("\"accuracy_rule\""), std::string::npos);
  EXPECT_NE(summary.find("gait_osmotic"), std::string::npos);
  // The report's stage-1 compartment curves are drawn from those series (they
  // were zero before stage 1 split one tibial surface).
  EXPECT_GT(series_max(summary, "stage 1 medial_force |F|"), 200.0);
  EXPECT_GT(series_max(summary, "stage 1 lateral_force |F|"), 200.0);
}
