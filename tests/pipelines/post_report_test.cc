// The post report's fixed pieces (pipelines/post_report.h): gait key instants
// of a force curve, and the summary's verdicts against the targets.
#include <gtest/gtest.h>

#include <cmath>

#include "pipelines/post_report.h"

namespace arthrosim::pipelines::post_report {
namespace {

TEST(PostReport, GaitPeaksOfADoubleHump) {
  std::vector<double> t, y;
  for (int k = 0; k <= 100; ++k) {
    t.push_back(k / 100.0);
    y.push_back(3 * std::exp(-std::pow((t.back() - 0.15) / 0.07, 2)) + 2.5 * std::exp(-std::pow((t.back() - 0.5) / 0.07, 2)) + 1);
  }
  const GaitPeaks g = gait_peaks(t, y);
  ASSERT_TRUE(g.found);
  EXPECT_EQ(g.first, 15);
  EXPECT_EQ(g.second, 50);
  EXPECT_NEAR(t[g.trough], 0.33, 0.02);  // the sum's minimum between the humps
  EXPECT_FALSE(gait_peaks({}, {}).found);
  // Part of stance only (a rising force): the windows' maxima are their edges, no peaks.
  EXPECT_FALSE(gait_peaks({0.10, 0.11, 0.12, 0.13, 0.14}, {2.3, 2.4, 2.5, 2.7, 2.9}).found);
}

TEST(PostReport, SummaryVerdicts) {
  KeyFigures k;
  k.peak1_bw = 3.0, k.peak2_bw = 3.8, k.trough_bw = 1.7, k.peak1_s = 0.16, k.peak2_s = 0.54;
  k.medial_share_peak1 = 0.7;
  k.force_figure = "fig-contact";
  KeyFigures::Scenario s;
  s.name = "gait";
  s.peak1_bw = 3.1, s.peak2_bw = 2.9, s.rms_si = 0.12, s.rms_frames = 60;
  s.rule_max_ratio = 0.2, s.rule_limit = 0.1, s.rule_steps = 3, s.rule_steps_over = 1;
  s.deflection_max_mm = 1.7, s.e1_max = 0.02, s.e1_min = -0.004, s.deflection_when = "first peak";
  s.angle_mean_deg = 12.3, s.angle_threshold_deg = 20, s.angle_samples = 359;
  k.scenarios = {s};
  const auto rows = summary_rows(k);
  auto find = [&](const std::string& what) {
    for (const auto& r : rows)
      if (r.quantity.find(what) != std::string::npos) return r;
    ADD_FAILURE() << what;
    return report_html::SummaryRow{};
  };
  using report_html::Verdict;
  EXPECT_EQ(find("stage 1 first peak").verdict, Verdict::kPass);
  EXPECT_EQ(find("stage 1 second peak").verdict, Verdict::kFail);  // 3.8 BW > 3.5
  EXPECT_EQ(find("stage 1 second peak").value, "3.8 BW at 0.54 s");
  EXPECT_EQ(find("trough").verdict, Verdict::kPass);
  EXPECT_EQ(find("medial share").value, "70 %");
  EXPECT_EQ(find("stage 2 peaks").verdict, Verdict::kPass);
  EXPECT_EQ(find("RMS difference").verdict, Verdict::kPass);  // 12 % <= the seed's 17 %
  EXPECT_EQ(find("accuracy rule").verdict, Verdict::kFail);    // one step over
  EXPECT_EQ(find("femoral deflection").verdict, Verdict::kInfo);
  EXPECT_EQ(find("femoral deflection").reference, "the seed: 1.1 mm at the first peak (its knee, its mesh)");
  EXPECT_EQ(find("angle error").verdict, Verdict::kPass);
  EXPECT_EQ(find("stage 1 first peak").figure, "fig-contact");
  // Nothing known, nothing stated.
  EXPECT_TRUE(summary_rows(KeyFigures{}).empty());
}

// Seed 001's conclusion: conditions formed only above 0.3 mJ/mm^2. The
// verdict follows the stated criterion (below <= a tenth of the smallest
// volume above, which must not be zero) on each side of its boundary.
TEST(PostReport, ShockwaveSeedConclusion) {
  using Runs = std::vector<std::pair<std::string, std::vector<EfdVolume>>>;
  const std::string yes = seed_conclusion_text(Runs{{"cartilage", {{0.12, 0.5}, {0.33, 5.0}, {0.8, 40.0}}}});
  EXPECT_NE(yes.find("cartilage"), std::string::npos) << yes;
  EXPECT_NE(yes.find("is reproduced"), std::string::npos) << yes;
  // Just over a tenth of the smallest volume above: not reproduced.
  const std::string no = seed_conclusion_text(Runs{{"menisci", {{0.12, 0.51}, {0.33, 5.0}, {0.8, 40.0}}}});
  EXPECT_NE(no.find("not reproduced"), std::string::npos) << no;
  // Nothing formed anywhere: not reproduced (the conditions must form above).
  EXPECT_NE(seed_conclusion_text(Runs{{"menisci", {{0.12, 0.0}, {0.8, 0.0}}}}).find("not reproduced"),
            std::string::npos);
  // Runs on one side only: no statement.
  EXPECT_TRUE(seed_conclusion_text(Runs{{"cartilage", {{0.33, 5.0}, {0.8, 40.0}}}}).empty());
}

}  // namespace
}  // namespace arthrosim::pipelines::post_report
