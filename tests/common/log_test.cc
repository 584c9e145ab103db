// Logging: level filtering, prefixes, level parsing, capture nesting, and
// whole lines under concurrent logging.
#include "common/log.h"

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <thread>

#include "common/error.h"

namespace arthrosim::common {
namespace {

// Restores the global level and program prefix after each test.
class LogTest : public ::testing::Test {
 protected:
  void SetUp() override { saved_ = log_level(); }
  void TearDown() override {
    set_log_level(saved_);
    set_log_program("");
  }
  LogLevel saved_ = LogLevel::kInfo;
};

TEST_F(LogTest, LevelFiltersMessages) {
  LogCapture cap;
  set_log_level(LogLevel::kWarn);
  log_error("e1");
  log_warn("w1");
  log_info("i1");
  log_debug("d1");
  set_log_level(LogLevel::kDebug);
  log_debug("d2");
  const auto e = cap.entries();
  ASSERT_EQ(e.size(), 3u);
  EXPECT_EQ(e[0].level, LogLevel::kError);
  EXPECT_EQ(e[0].message, "e1");
  EXPECT_EQ(e[1].message, "w1");
  EXPECT_EQ(e[2].message, "d2");
  EXPECT_EQ(cap.text(), "error: e1\nwarning: w1\ndebug: d2\n");
  EXPECT_TRUE(cap.contains(LogLevel::kWarn, "w"));
  EXPECT_FALSE(cap.contains(LogLevel::kInfo, "i1"));
}

TEST_F(LogTest, ProgramPrefix) {
  LogCapture cap;
  set_log_program("arthrosim-prepare");
  log_info("remeshing femoral cartilage");
  EXPECT_EQ(cap.text(), "arthrosim-prepare: info: remeshing femoral cartilage\n");
}

TEST_F(LogTest, ParseAndFlags) {
  EXPECT_EQ(parse_log_level("error"), LogLevel::kError);
  EXPECT_EQ(parse_log_level("warn"), LogLevel::kWarn);
  EXPECT_EQ(parse_log_level("warning"), LogLevel::kWarn);
  EXPECT_EQ(parse_log_level("info"), LogLevel::kInfo);
  EXPECT_EQ(parse_log_level("debug"), LogLevel::kDebug);
  try {
    parse_log_level("loud");
    FAIL();
  } catch (const InputError& e) {
    EXPECT_THAT(e.what(), ::testing::HasSubstr("expected a log level (error, warn, info, debug), found 'loud'"));
  }
  EXPECT_EQ(log_level_from_flags(false, false), LogLevel::kInfo);
  EXPECT_EQ(log_level_from_flags(true, false), LogLevel::kDebug);
  EXPECT_EQ(log_level_from_flags(false, true), LogLevel::kWarn);
  EXPECT_EQ(log_level_from_flags(true, true), LogLevel::kWarn);
}

TEST_F(LogTest, CapturesNestInnermostReceives) {
  LogCapture outer;
  log_info("a");
  {
    LogCapture inner;
    log_info("b");
    EXPECT_EQ(inner.text(), "info: b\n");
  }
  log_info("c");
  EXPECT_EQ(outer.text(), "info: a\ninfo: c\n");
}

TEST_F(LogTest, ConcurrentMessagesStayWhole) {
  LogCapture cap;
  std::vector<std::thread> threads;
  for (int t = 0; t < 4; ++t) {
    threads.emplace_back([t] {
      for (int i = 0; i < 200; ++i) log_info("thread " + std::to_string(t) + " message " + std::to_string(i));
    });
  }
  for (auto& th : threads) th.join();
  const auto e = cap.entries();
  ASSERT_EQ(e.size(), 800u);
  std::string text = cap.text();
  int lines = 0;
  for (size_t p = 0; (p = text.find('\n', p)) != std::string::npos; ++p) ++lines;
  EXPECT_EQ(lines, 800);
}

}  // namespace
}  // namespace arthrosim::common
