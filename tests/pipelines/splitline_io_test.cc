// Split-line map readers (pipelines/splitline.h): SVG path commands, shapes, transforms,
// the y flip, CSV sections, and file:line errors.
#include <gtest/gtest.h>

#include <cmath>
#include <numbers>

#include "common/error.h"
#include "pipelines/splitline.h"

namespace arthrosim::pipelines {
namespace {

constexpr double kPi = std::numbers::pi;

std::string svg(const std::string& body) {
  return "<?xml version=\"1.0\"?>\n<svg xmlns=\"http://www.w3.org/2000/svg\">\n"
         "<path d=\"M 0,0 L 100,0 L 100,-100 L 0,-100 Z\"/>\n" + body + "</svg>\n";
}

// Message of the InputError thrown by f, or "" when nothing is thrown.
template <typename F>
std::string error_of(F f) {
  try {
    f();
  } catch (const common::InputError& e) {
    return e.what();
  }
  return "";
}

TEST(SplitlineSvg, OutlineAndLinesWithYFlipped) {
  const auto m = parse_splitline_svg(svg("<polyline points=\"10,-10 20,-20\"/>\n"), "t.svg", 1.0);
  ASSERT_EQ(m.outline.rows(), 4);
  EXPECT_DOUBLE_EQ(m.outline(2, 0), 100.0);
  EXPECT_DOUBLE_EQ(m.outline(2, 1), 100.0);  // SVG y = -100 -> map y = +100
  ASSERT_EQ(m.lines.size(), 1u);
  // The line goes from (10, 10) to (20, 20) in map coordinates: 45 degrees.
  EXPECT_NEAR(m.lines[0].points(1, 1), 20.0, 1e-12);
  ASSERT_EQ(m.samples.rows(), 14);  // length 14.14, spacing 1 -> floor = 14 samples
  for (Eigen::Index s = 0; s < m.angle_rad.size(); ++s) EXPECT_NEAR(m.angle_rad(s), kPi / 4, 1e-12);
  EXPECT_NEAR(m.samples(0, 0), 10.0 + 0.5 * std::sqrt(200.0) / 14 / std::sqrt(2.0), 1e-12);
  EXPECT_FALSE(m.synthetic);
}

TEST(SplitlineSvg, RelativeAndAbsoluteCommandsAgree) {
  const auto a = parse_splitline_svg(svg("<path d=\"M 10 10 L 20 10 H 30 V 20 C 30 30 40 30 40 20\"/>"), "a.svg", 0.5);
  const auto r = parse_splitline_svg(svg("<path d=\"m10,10 l10,0 h10 v10 c0,10 10,10 10,0\"/>"), "r.svg", 0.5);
  ASSERT_EQ(a.lines[0].points.rows(), r.lines[0].points.rows());
  EXPECT_LT((a.lines[0].points - r.lines[0].points).cwiseAbs().maxCoeff(), 1e-12);
  // L, H, V give 4 points, the cubic 16 more; its end point and midpoint (Bernstein at
  // t = 1/2: (p0 + 3 c1 + 3 c2 + p3)/8 = (35, 27.5) in SVG) are exact.
  ASSERT_EQ(a.lines[0].points.rows(), 4 + 16);
  EXPECT_NEAR(a.lines[0].points(19, 0), 40.0, 1e-12);
  EXPECT_NEAR(a.lines[0].points(19, 1), -20.0, 1e-12);
  EXPECT_NEAR(a.lines[0].points(4 + 7, 0), 35.0, 1e-12);
  EXPECT_NEAR(a.lines[0].points(4 + 7, 1), -27.5, 1e-12);
  // Implicit lineto after moveto and repeated pairs.
  const auto i = parse_splitline_svg(svg("<path d=\"M0 0 5 0 5 5\"/>"), "i.svg", 1.0);
  EXPECT_EQ(i.lines[0].points.rows(), 3);
}

TEST(SplitlineSvg, GroupTransformsCompose) {
  const auto m = parse_splitline_svg(
      svg("<g transform=\"translate(10,5) scale(2)\"><g transform=\"matrix(0,1,-1,0,0,0)\">"
          "<line x1=\"1\" y1=\"0\" x2=\"2\" y2=\"0\"/></g></g>\n"),
      "g.svg", 1.0);
  // matrix(0,1,-1,0) maps (1,0) -> (0,1); scale 2 -> (0,2); translate -> (10,7); flip y.
  ASSERT_EQ(m.lines.size(), 1u);
  EXPECT_NEAR(m.lines[0].points(0, 0), 10.0, 1e-12);
  EXPECT_NEAR(m.lines[0].points(0, 1), -7.0, 1e-12);
  EXPECT_NEAR(m.lines[0].points(1, 1), -9.0, 1e-12);
  EXPECT_NEAR(std::abs(m.angle_rad(0)), kPi / 2, 1e-12);  // vertical line (axial)
}

TEST(SplitlineSvg, RegionsFromGroupIdsAndAttributes) {
  const auto m = parse_splitline_svg(
      svg("<g id=\"medial\"><polyline points=\"1,1 2,2\"/><line data-region=\"lateral\" x1=\"0\" y1=\"0\" x2=\"3\" "
          "y2=\"0\"/></g><line x1=\"0\" y1=\"0\" x2=\"0\" y2=\"3\"/>"),
      "r.svg", 1.0);
  ASSERT_EQ(m.lines.size(), 3u);
  EXPECT_EQ(m.lines[0].region, "medial");
  EXPECT_EQ(m.lines[1].region, "lateral");
  EXPECT_EQ(m.lines[2].region, "all");
}

TEST(SplitlineSvg, ErrorsNameFileAndLine) {
  auto msg = error_of([] { parse_splitline_svg(svg("\n<path d=\"M 0 0 Q 1 1 2 2\"/>"), "q.svg"); });
  EXPECT_NE(msg.find("q.svg:5: error: unsupported path command 'Q'"), std::string::npos) << msg;
  msg = error_of([] { parse_splitline_svg(svg("<polygon points=\"0,0 1,0 1,1\"/>"), "two.svg"); });
  EXPECT_NE(msg.find("two.svg:4: error: a second closed shape (the outline was already given on line 3)"),
            std::string::npos)
      << msg;
  msg = error_of([] { parse_splitline_svg(svg("<polyline points=\"0,0 1,0 1\"/>"), "odd.svg"); });
  EXPECT_NE(msg.find("odd.svg:4: error: <polyline> points: expected an even count"), std::string::npos) << msg;
  msg = error_of([] { parse_splitline_svg(svg("<g transform=\"skewX(3)\"><line x1=\"0\" y1=\"0\" x2=\"1\" y2=\"1\"/></g>"), "s.svg"); });
  EXPECT_NE(msg.find("s.svg:4: error: unsupported transform 'skewX'"), std::string::npos) << msg;
  msg = error_of([] { parse_splitline_svg("<svg>\n<polyline points=\"0,0 1,1\"/>\n</svg>", "none.svg"); });
  EXPECT_NE(msg.find("none.svg:3: error: expected one closed path"), std::string::npos) << msg;
  msg = error_of([] { parse_splitline_svg(svg("<g><line x1=\"0\" y1=\"0\" x2=\"1\" y2=\"1\"/></svg>"), "nest.svg"); });
  EXPECT_NE(msg.find("nest.svg:4: error: closing tag </svg> does not match <g>"), std::string::npos) << msg;
  msg = error_of([] { parse_splitline_svg(svg("<line x1=\"0\" y1=\"abc\" x2=\"1\" y2=\"1\"/>"), "num.svg"); });
  EXPECT_NE(msg.find("num.svg:4: error: expected a number in attribute y1"), std::string::npos) << msg;
  msg = error_of([] { read_splitline_map("/nonexistent/map.svg"); });
  EXPECT_NE(msg.find("/nonexistent/map.svg: error: cannot open"), std::string::npos) << msg;
  msg = error_of([] { read_splitline_map("map.txt"); });
  EXPECT_NE(msg.find("expected a split-line map ending in .svg or .csv"), std::string::npos) << msg;
}

// Found by fuzz_splitline: a number beyond the double range (1e999) made
// std::stod throw std::out_of_range out of the reader.
TEST(SplitlineSvg, NumberOutOfRangeIsAnInputError) {
  const auto msg = error_of([] { parse_splitline_svg(svg("<polyline points=\"0,0 1e999,1\"/>"), "big.svg"); });
  EXPECT_NE(msg.find("big.svg:4: error: number out of range in <polyline> points: '1e999'"), std::string::npos) << msg;
}

// Found by fuzz_splitline: a split line 10^5 times longer than the outline
// was sampled at 1/100 of the outline's diagonal (10^7 samples, a timeout).
TEST(SplitlineSvg, SplitLinesFarLongerThanTheOutlineAreRefused) {
  const auto msg = error_of([] { parse_splitline_svg(svg("<polyline points=\"0,0 1e7,0\"/>"), "long.svg"); });
  EXPECT_NE(msg.find("long.svg: error: split lines of total length"), std::string::npos) << msg;
  EXPECT_NE(msg.find("would give more than 1e6 samples"), std::string::npos) << msg;
}

const char* kCsv =
    "# test map\n"
    "[samples]\n"
    "x,y,angle_deg,region\n"
    "1,2,30,medial\n"
    "3,4,-100,lateral\n"
    "\n"
    "[outline]\n"
    "x,y\n"
    "0,0\n10,0\n10,10\n0,10\n";

TEST(SplitlineCsv, SamplesOutlineAndRegions) {
  const auto m = parse_splitline_csv(kCsv, "m.csv");
  ASSERT_EQ(m.samples.rows(), 2);
  EXPECT_DOUBLE_EQ(m.samples(1, 1), 4.0);
  EXPECT_NEAR(m.angle_rad(0), kPi / 6, 1e-15);
  EXPECT_NEAR(m.angle_rad(1), 80.0 * kPi / 180, 1e-14);  // -100 deg is the line at 80 deg
  EXPECT_EQ(m.region[1], "lateral");
  EXPECT_EQ(m.outline.rows(), 4);
  EXPECT_NEAR(m.spacing, std::sqrt(8.0), 1e-12);
}

TEST(SplitlineCsv, ErrorsNameFileAndLine) {
  std::string bad = kCsv;
  bad.replace(bad.find("3,4,-100"), 8, "3,x4,-10");
  auto msg = error_of([&] { parse_splitline_csv(bad, "b.csv"); });
  EXPECT_NE(msg.find("b.csv:5: error: expected a number for y, found 'x4'"), std::string::npos) << msg;
  msg = error_of([] { parse_splitline_csv("[samples]\nx,y\n", "h.csv"); });
  EXPECT_NE(msg.find("h.csv:2: error: expected the header 'x,y,angle_deg'"), std::string::npos) << msg;
  msg = error_of([] { parse_splitline_csv("[samples]\nx,y,angle_deg\n1,2\n", "f.csv"); });
  EXPECT_NE(msg.find("f.csv:3: error: expected 3 fields"), std::string::npos) << msg;
  msg = error_of([] { parse_splitline_csv("[samples]\nx,y,angle_deg\n1,2,3\n", "o.csv"); });
  EXPECT_NE(msg.find("o.csv:3: error: expected an [outline] section with at least 3 points, found 0"),
            std::string::npos)
      << msg;
  msg = error_of([] { parse_splitline_csv("1,2,3\n", "s.csv"); });
  EXPECT_NE(msg.find("s.csv:1: error: expected a section header"), std::string::npos) << msg;
}

TEST(SplitlineFiles, BundledSyntheticMapsAgree) {
  const std::string dir = std::string(ARTHROSIM_SOURCE_DIR) + "/data/splitlines/";
  const auto s = read_splitline_map(dir + "synthetic_femur.svg");
  const auto c = read_splitline_map(dir + "synthetic_femur.csv");
  EXPECT_TRUE(s.synthetic);
  EXPECT_TRUE(c.synthetic);
  EXPECT_EQ(s.lines.size(), 99u);
  // The SVG's outline is a Catmull-Rom curve through the CSV's 48 outline points: every
  // 16th point is one of them (the moveto point, then 16 samples per segment, the closing
  // duplicate dropped; 4 decimals written, so 1e-3 tolerance).
  ASSERT_EQ(s.outline.rows(), 48 * 16);
  for (int k = 0; k < 48; ++k) {
    EXPECT_LT((s.outline.row(16 * k) - c.outline.row(k)).norm(), 1e-3) << k;
  }
}

}  // namespace
}  // namespace arthrosim::pipelines
