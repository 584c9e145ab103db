// Progress display: the plain (non-TTY) line format and when lines appear,
// with a fake clock so the output is exact; the TTY bar format; silence
// under --quiet.
#include "common/progress.h"

#include <gtest/gtest.h>

#include <sstream>

#include "common/log.h"

namespace arthrosim::common {
namespace {

struct FakeClock {
  double t = 100.0;
  std::function<double()> fn() {
    return [this] { return t; };
  }
};

TEST(Progress, PlainLinesEveryTenPercentWithEta) {
  FakeClock clock;
  std::ostringstream out;
  ProgressOptions o;
  o.mode = ProgressOptions::Mode::kPlain;
  o.out = &out;
  o.clock = clock.fn();
  o.plain_interval_s = 1e9;  // percentage lines only
  {
    Progress p("shell steps", 200, o);
    for (int i = 0; i < 200; ++i) {
      clock.t += 0.5;  // 0.5 s per step -> 100 s total
      p.step();
    }
  }
  // Lines at 10%, 20%, ..., 90% and the final line; 10% = 20 steps = 10 s,
  // eta = 10 s * 180/20 = 90 s = "1 min 30 s".
  std::istringstream in(out.str());
  std::vector<std::string> lines;
  for (std::string l; std::getline(in, l);) lines.push_back(l);
  ASSERT_EQ(lines.size(), 10u) << out.str();
  EXPECT_EQ(lines[0], "shell steps: 10% (20/200) elapsed 10.0 s, eta 1 min 30 s");
  EXPECT_EQ(lines[4], "shell steps: 50% (100/200) elapsed 50.0 s, eta 50.0 s");
  EXPECT_EQ(lines[8], "shell steps: 90% (180/200) elapsed 1 min 30 s, eta 10.0 s");
  EXPECT_EQ(lines[9], "shell steps: done 200/200 in 1 min 40 s");
}

TEST(Progress, PlainTimeTriggeredLinesAndEarlyStop) {
  FakeClock clock;
  std::ostringstream out;
  ProgressOptions o;
  o.mode = ProgressOptions::Mode::kPlain;
  o.out = &out;
  o.clock = clock.fn();
  o.percent_step = 50;
  o.plain_interval_s = 30.0;
  Progress p("frames", 1000, o);
  clock.t += 31.0;
  p.update(10);  // 1%, but 31 s since the start -> a line
  clock.t += 1.0;
  p.update(20);  // nothing
  clock.t += 1.0;
  p.update(500);  // 50% -> a line
  p.finish();     // stopped early
  p.update(600);  // after finish: nothing
  EXPECT_EQ(out.str(),
            "frames: 1% (10/1000) elapsed 31.0 s, eta 51 min 09 s\n"
            "frames: 50% (500/1000) elapsed 33.0 s, eta 33.0 s\n"
            "frames: stopped at 500/1000 after 33.0 s\n");
}

TEST(Progress, TtyBarRedrawsInPlace) {
  FakeClock clock;
  std::ostringstream out;
  ProgressOptions o;
  o.mode = ProgressOptions::Mode::kTty;
  o.out = &out;
  o.clock = clock.fn();
  o.tty_interval_s = 0.1;
  Progress p("contact", 4, o);
  clock.t += 1.0;
  p.step();  // 25%: drawn
  p.step();  // same time: not redrawn (interval)
  clock.t += 1.0;
  p.step(2);  // done: final line with newline
  EXPECT_EQ(out.str(),
            "\rcontact [=======>                      ]  25% 1/4 1/s eta 3.0 s\033[K"
            "\rcontact [==============================] 100% 4/4 2/s in 2.0 s\033[K\n");
}

TEST(Progress, QuietLevelSilences) {
  const LogLevel saved = log_level();
  set_log_level(LogLevel::kWarn);
  std::ostringstream out;
  ProgressOptions o;
  o.mode = ProgressOptions::Mode::kPlain;
  o.out = &out;
  {
    Progress p("x", 10, o);
    p.update(10);
  }
  set_log_level(saved);
  EXPECT_EQ(out.str(), "");
}

TEST(Progress, FormatDuration) {
  EXPECT_EQ(format_duration(0.04), "0.0 s");
  EXPECT_EQ(format_duration(59.94), "59.9 s");
  EXPECT_EQ(format_duration(61.0), "1 min 01 s");
  EXPECT_EQ(format_duration(7380.0), "2 h 03 min");
  EXPECT_EQ(format_duration(-1.0), "?");
}

}  // namespace
}  // namespace arthrosim::common
