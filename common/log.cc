// Logging (see log.h).
#include "common/log.h"

#include <atomic>
#include <cstdio>
#include <mutex>

#include "common/error.h"

namespace arthrosim::common {
namespace {

std::atomic<int> g_level{static_cast<int>(LogLevel::kInfo)};
std::mutex g_mutex;            // guards g_program, g_capture and stderr lines
std::string g_program;         // prefix, may be empty
LogCapture* g_capture = nullptr;  // innermost active capture

std::string format_line(LogLevel level, const std::string& message) {
  std::string line;
  if (!g_program.empty()) line += g_program + ": ";
  line += log_level_name(level);
  line += ": ";
  line += message;
  line += '\n';
  return line;
}

}  // namespace

void set_log_level(LogLevel level) { g_level.store(static_cast<int>(level)); }
LogLevel log_level() { return static_cast<LogLevel>(g_level.load()); }

const char* log_level_name(LogLevel level) {
  switch (level) {
    case LogLevel::kError: return "error";
    case LogLevel::kWarn: return "warning";
    case LogLevel::kInfo: return "info";
    case LogLevel::kDebug: return "debug";
  }
  return "?";
}

LogLevel parse_log_level(const std::string& text) {
  if (text == "error") return LogLevel::kError;
  if (text == "warn" || text == "warning") return LogLevel::kWarn;
  if (text == "info") return LogLevel::kInfo;
  if (text == "debug") return LogLevel::kDebug;
  throw InputError("expected a log level (error, warn, info, debug), found '" + text + "'");
}

LogLevel log_level_from_flags(bool verbose, bool quiet) {
  if (quiet) return LogLevel::kWarn;
  if (verbose) return LogLevel::kDebug;
  return LogLevel::kInfo;
}

void set_log_program(const std::string& program) {
  std::lock_guard<std::mutex> lock(g_mutex);
  g_program = program;
}

void log(LogLevel level, const std::string& message) {
  if (!log_enabled(level)) return;
  std::lock_guard<std::mutex> lock(g_mutex);
  const std::string line = format_line(level, message);
  if (g_capture != nullptr) {
    g_capture->entries_.push_back({level, message});
    g_capture->text_ += line;
    return;
  }
  // One fwrite per line keeps lines whole when several threads log.
  std::fwrite(line.data(), 1, line.size(), stderr);
  std::fflush(stderr);
}

LogCapture::LogCapture() {
  std::lock_guard<std::mutex> lock(g_mutex);
  previous_ = g_capture;
  g_capture = this;
}

LogCapture::~LogCapture() {
  std::lock_guard<std::mutex> lock(g_mutex);
  g_capture = previous_;
}

std::vector<LogCapture::Entry> LogCapture::entries() const {
  std::lock_guard<std::mutex> lock(g_mutex);
  return entries_;
}

std::string LogCapture::text() const {
  std::lock_guard<std::mutex> lock(g_mutex);
  return text_;
}

bool LogCapture::contains(LogLevel level, const std::string& needle) const {
  std::lock_guard<std::mutex> lock(g_mutex);
  for (const Entry& e : entries_) {
    if (e.level == level && e.message.find(needle) != std::string::npos) return true;
  }
  return false;
}

}  // namespace arthrosim::common
