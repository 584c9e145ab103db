// Trials as OpenSim writes them: the ExternalLoads XML reader
// (musculoskeletal/external_loads.h), a trial that names one instead of
// column mappings (the bundled lenhart2015 overground_17 trial), every
// kinematics column by name, and the time window of a scene.
#include "musculoskeletal/external_loads.h"

#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <functional>
#include <sstream>

#include "common/error.h"
#include "tests/test_support.h"
#include "common/storage.h"
#include "musculoskeletal/gait_trial.h"
#include "musculoskeletal/knee_loads.h"

namespace arthrosim::musculoskeletal {
namespace {

namespace fs = std::filesystem;
const fs::path kTrialDir = fs::path(ARTHROSIM_SOURCE_DIR) / "data/trials/lenhart2015_overground17";

using test_support::message_of;
using test_support::read_text;

fs::path scratch(const std::string& name) { return test_support::fresh_scratch_dir("external_loads_" + name); }

TEST(ExternalLoads, ReadsTheBundledFile) {
  const ExternalLoadsSpec s = read_external_loads((kTrialDir / "overground_17_ext_loads.xml").string());
  ASSERT_EQ(s.forces.size(), 3u);
  EXPECT_EQ(s.forces[1].name, "FP2");
  EXPECT_EQ(s.forces[1].applied_to_body, "calcn_r");
  EXPECT_EQ(s.forces[1].force_identifier, "ground_force_2_v");
  EXPECT_EQ(s.forces[1].point_identifier, "ground_force_2_p");
  EXPECT_EQ(s.forces[1].torque_identifier, "ground_torque_2_");
  EXPECT_EQ(s.forces[0].applied_to_body, "calcn_l");
  EXPECT_EQ(s.forces[1].line, 19);
  EXPECT_EQ(fs::path(s.datafile), kTrialDir / "overground_17_grf.mot");
  // OpenSim's identifier rule: the three columns whose labels start with it.
  const common::StorageTable t = common::read_storage(s.datafile, [](const std::string&) { return false; });
  const auto c = identifier_columns(t.labels, "ground_force_2_p", s.datafile, s.file, 1);
  EXPECT_EQ(t.labels[c[0]], "ground_force_2_px");
  EXPECT_EQ(t.labels[c[2]], "ground_force_2_pz");
}

TEST(ExternalLoads, BadFilesGiveFileLineErrors) {
  const std::string good = read_text(kTrialDir / "overground_17_ext_loads.xml");
  auto err = [&](const std::string& from, const std::string& to) {
    std::string x = good;
    const auto p = x.find(from);
    EXPECT_NE(p, std::string::npos) << from;
    x.replace(p, from.size(), to);
    return message_of([&] { parse_external_loads(x, "el.xml", ""); });
  };
  EXPECT_NE(err("<force_expressed_in_body>ground</force_expressed_in_body>",
                "<force_expressed_in_body>calcn_l</force_expressed_in_body>")
                .find("el.xml:9: error: ExternalForce 'FP1': expected force_expressed_in_body ground"),
            std::string::npos);
  EXPECT_NE(err("<datafile>overground_17_grf.mot</datafile>", "<datafile></datafile>").find("el.xml:50: error: expected a <datafile>"),
            std::string::npos);
  EXPECT_NE(err("name=\"FP3\"", "name=\"FP1\"").find("el.xml:33: error: duplicate ExternalForce 'FP1' (first on line 5)"),
            std::string::npos);
  EXPECT_NE(err("<applied_to_body>calcn_r</applied_to_body>", "").find("el.xml:19: error: ExternalForce 'FP2': expected <applied_to_body>"),
            std::string::npos);
  EXPECT_NE(err("</ExternalLoads>", "").find("el.xml:"), std::string::npos);  // malformed XML
  EXPECT_NE(message_of([] { parse_external_loads("<OpenSimDocument/>", "e.xml", ""); })
                .find("e.xml:1: error: expected an <ExternalLoads> element"),
            std::string::npos);
  // An identifier matching other than 3 columns names the identifier's line.
  const std::string m = message_of([] {
    identifier_columns({"time", "a_x", "a_y"}, "a_", "d.mot", "el.xml", 17);
  });
  EXPECT_NE(m.find("el.xml:17: error: identifier 'a_': expected 3 columns of d.mot starting with it, found 2 (a_x, a_y)"),
            std::string::npos)
      << m;
}

// The bundled measured trial: the ExternalLoads file replaces the column
// mapping; the mass and height are not given (the model's own bodies give
// them); every kinematics column is kept by name.
TEST(OpenSimTrial, BundledLenhartTrial) {
  const GaitTrial t = load_gait_trial((kTrialDir / "trial.yaml").string());
  EXPECT_FALSE(t.synthetic);
  EXPECT_EQ(t.body_mass_kg, 0.0);
  EXPECT_FALSE(t.has_joint_angles);
  EXPECT_FALSE(t.has_grf);  // no foot_body: the model picks the forces on its bodies
  ASSERT_EQ(t.external_forces.size(), 3u);
  const TrialExternalForce& fp2 = t.external_forces[1];
  EXPECT_EQ(fp2.body, "calcn_r");
  EXPECT_TRUE(fp2.has_point && fp2.has_torque);
  // IK at 200 Hz from 0 to 2.36 s, resampled to 100 Hz: 237 samples.
  EXPECT_EQ(t.num_samples(), 237);
  EXPECT_NEAR(t.time(121), 1.21, 1e-12);
  ASSERT_EQ(t.kinematics_labels.size(), 52u);
  const int knee = t.kinematics_column("knee_flex_r"), tx = t.kinematics_column("knee_tx_r");
  ASSERT_GE(knee, 0);
  ASSERT_GE(tx, 0);
  EXPECT_EQ(t.kinematics_column("no_such_coordinate"), -1);
  // Angles in radians, translations in metres: the knee of this walk stays
  // within -10..75 deg, knee_tx_r within a few cm.
  EXPECT_LT(t.kinematics_q.col(knee).maxCoeff(), 75.0 * M_PI / 180.0);
  EXPECT_GT(t.kinematics_q.col(knee).maxCoeff(), 55.0 * M_PI / 180.0);
  EXPECT_LT(t.kinematics_q.col(tx).cwiseAbs().maxCoeff(), 0.05);
  // Right stance: the vertical force on calcn_r is above 10 N from about
  // 1.27 to 1.94 s (references.md: 1.263-1.942 s) and zero in the right swing.
  int first = -1, last = -1;
  for (int i = 0; i < t.num_samples(); ++i)
    if (fp2.force_W(i, 1) > 0) {
      if (first < 0) first = i;
      last = i;
    }
  EXPECT_NEAR(t.time(first), 1.27, 0.015);
  EXPECT_NEAR(t.time(last), 1.94, 0.015);
  const double peak_bw = fp2.force_W.col(1).maxCoeff() / (62.0 * 9.80665);
  // The file's own peak is 846.8 N = 1.39 BW at 1.450 s (2000 Hz); the 100 Hz
  // grid samples it linearly.
  EXPECT_GT(peak_bw, 1.3);
  EXPECT_LE(peak_bw, 846.85 / (62.0 * 9.80665));
  // The centre of pressure lies under the walk (pelvis_tx moves forward).
  EXPECT_GT(fp2.point_W(150, 0), -1.0);
  EXPECT_EQ(fp2.point_W(230, 0), 0.0);  // swing: zeroed with the force
  // The generic leg chain cannot use it, and says why.
  EXPECT_NE(message_of([&] { leg_model_for_trial(t); }).find("needs subject_mass_kg and subject_height_m"),
            std::string::npos);
}

TEST(OpenSimTrial, FootBodySelectsTheGroundReaction) {
  const fs::path dir = scratch("foot_body");
  for (const char* f : {"overground_17_ik.mot", "overground_17_ext_loads.xml", "overground_17_grf.mot"})
    fs::copy_file(kTrialDir / f, dir / f);
  std::string yaml = read_text(kTrialDir / "trial.yaml");
  std::ofstream(dir / "trial.yaml") << yaml << "foot_body: calcn_r\n";
  const GaitTrial t = load_gait_trial((dir / "trial.yaml").string());
  ASSERT_TRUE(t.has_grf);
  EXPECT_EQ((t.grf_force_W - t.external_forces[1].force_W).cwiseAbs().maxCoeff(), 0.0);
  EXPECT_EQ((t.grf_cop_W - t.external_forces[1].point_W).cwiseAbs().maxCoeff(), 0.0);
  // Two plates act on calcn_l: not one ground reaction.
  std::ofstream(dir / "trial.yaml") << yaml << "foot_body: calcn_l\n";
  const std::string m = message_of([&] { load_gait_trial((dir / "trial.yaml").string()); });
  EXPECT_NE(m.find("trial.yaml:16: error: foot_body 'calcn_l': expected exactly one ExternalForce"), std::string::npos)
      << m;
  EXPECT_NE(m.find("found 2 (FP1 -> calcn_l, FP2 -> calcn_r, FP3 -> calcn_l)"), std::string::npos) << m;
  // An ExternalLoads file and a grf_file exclude each other.
  std::ofstream(dir / "trial.yaml") << yaml << "grf_file: overground_17_grf.mot\n";
  EXPECT_NE(message_of([&] { read_trial_description((dir / "trial.yaml").string()); })
                .find("expected either grf_file or external_loads_file, found both"),
            std::string::npos);
}

// opensim-jam's walking window 1.21-2.32 s at 100 Hz: 112 frames.
TEST(OpenSimTrial, TimeWindow) {
  const GaitTrial t = load_gait_trial((kTrialDir / "trial.yaml").string());
  const auto [first, last] = frames_in_window(t, 1.21, 2.32);
  EXPECT_EQ(first, 121);
  EXPECT_EQ(last, 232);
  EXPECT_EQ(last - first + 1, 112);
  EXPECT_EQ(frames_in_window(t, NAN, NAN), std::make_pair(0, 236));
  EXPECT_EQ(frames_in_window(t, 1.205, 1.215), std::make_pair(121, 121));
  EXPECT_NE(message_of([&] { frames_in_window(t, 2.0, 1.0); }).find("expected start <= end"), std::string::npos);
  EXPECT_NE(message_of([&] { frames_in_window(t, 1.0, 3.0); }).find("expected a window inside the trial"),
            std::string::npos);
  EXPECT_NE(message_of([&] { frames_in_window(t, 1.201, 1.209); }).find("found none"), std::string::npos);
}

}  // namespace
}  // namespace arthrosim::musculoskeletal
