#pragma once
// Progress display for long loops.
//  - On a terminal (isatty(stderr)): one line redrawn in place,
//      "label [=========>          ] 45% 450/1000 12.3/s eta 44 s"
//    at most every `tty_interval_s`.
//  - Otherwise (CI logs, redirected output): plain lines, one each time the
//    fraction done crosses a multiple of `percent_step` or `plain_interval_s`
//    seconds have passed since the last line, whichever comes first:
//      "label: 30% (300/1000) elapsed 4.1 s, eta 9.6 s"
//    and a final "label: done 1000/1000 in 13.7 s" line.
// Nothing is printed when the log level is below info (--quiet). The display
// is not thread-safe: call step()/update() from one thread (e.g. after an
// OpenMP loop chunk, or with an atomic counter read by the master thread).
#include <cstdint>
#include <functional>
#include <iosfwd>
#include <string>

namespace arthrosim::common {

struct ProgressOptions {
  enum class Mode { kAuto, kTty, kPlain, kOff };
  /// kAuto: kTty if stderr is a terminal, kPlain otherwise.
  Mode mode = Mode::kAuto;
  /// Plain mode: a line every `percent_step` percent (1..100).
  int percent_step = 10;
  /// Plain mode: also a line after this many seconds without one [s].
  double plain_interval_s = 30.0;
  /// TTY mode: minimum time between redraws [s].
  double tty_interval_s = 0.1;
  /// Output stream; nullptr = std::cerr.
  std::ostream* out = nullptr;
  /// Clock in seconds (monotonic); empty = std::chrono::steady_clock. Tests
  /// inject a fake clock to get deterministic output.
  std::function<double()> clock;
};

class Progress {
 public:
  /// `total` work units (> 0; 0 gives no output at all).
  Progress(std::string label, std::int64_t total, ProgressOptions options = {});
  ~Progress();  ///< calls finish() if not called yet
  Progress(const Progress&) = delete;
  Progress& operator=(const Progress&) = delete;

  /// Adds `n` units done.
  void step(std::int64_t n = 1) { update(done_ + n); }
  /// Sets the number of units done (clamped to [0, total]).
  void update(std::int64_t done);
  /// Prints the final line (once).
  void finish();
  std::int64_t done() const { return done_; }

 private:
  void print_plain(double now, bool final_line);
  void print_tty(double now, bool final_line);
  std::string label_;
  std::int64_t total_;
  std::int64_t done_ = 0;
  ProgressOptions options_;
  ProgressOptions::Mode mode_;
  std::ostream* out_;
  double start_ = 0.0;
  double last_print_ = 0.0;
  int last_percent_printed_ = 0;
  bool finished_ = false;
};

/// "1.2 s", "3 min 05 s", "2 h 03 min" (for messages).
std::string format_duration(double seconds);

}  // namespace arthrosim::common
