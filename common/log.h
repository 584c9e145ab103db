#pragma once
// Logging with levels. Messages go to stderr as "<program>: <level>: <text>"
// (the program prefix only when set_log_program was called), one line per
// message, whole lines only (safe to call from several threads).
//
// Levels, from least to most verbose: error < warn < info < debug. A message
// is printed when its level <= the global level (default info). Executables
// map --quiet to warn and --verbose to debug (log_level_from_flags).
#include <string>
#include <vector>

namespace arthrosim::common {

enum class LogLevel { kError = 0, kWarn = 1, kInfo = 2, kDebug = 3 };

void set_log_level(LogLevel level);
LogLevel log_level();
inline bool log_enabled(LogLevel level) { return static_cast<int>(level) <= static_cast<int>(log_level()); }

/// "error", "warn" (or "warning"), "info", "debug" -> level; throws InputError otherwise.
LogLevel parse_log_level(const std::string& text);
/// "error", "warning", "info", "debug" (as used in the prefix).
const char* log_level_name(LogLevel level);
/// --quiet -> warn, --verbose -> debug, neither -> info (quiet wins if both).
LogLevel log_level_from_flags(bool verbose, bool quiet);

/// Prefix of every message, usually the executable name; empty = none.
void set_log_program(const std::string& program);

void log(LogLevel level, const std::string& message);
inline void log_error(const std::string& message) { log(LogLevel::kError, message); }
inline void log_warn(const std::string& message) { log(LogLevel::kWarn, message); }
inline void log_info(const std::string& message) { log(LogLevel::kInfo, message); }
inline void log_debug(const std::string& message) { log(LogLevel::kDebug, message); }

/// While alive, messages that pass the level filter are recorded here instead
/// of being printed (for tests). Captures nest; the innermost one receives.
class LogCapture {
 public:
  struct Entry {
    LogLevel level;
    std::string message;
  };
  LogCapture();
  ~LogCapture();
  LogCapture(const LogCapture&) = delete;
  LogCapture& operator=(const LogCapture&) = delete;

  std::vector<Entry> entries() const;
  /// Every captured line as it would have been printed, '\n'-terminated.
  std::string text() const;
  /// True if some captured message at `level` contains `needle`.
  bool contains(LogLevel level, const std::string& needle) const;

 private:
  std::vector<Entry> entries_;
  std::string text_;
  LogCapture* previous_;
  friend void log(LogLevel, const std::string&);
};

}  // namespace arthrosim::common
