// Progress display (see progress.h).
#include "common/progress.h"

#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <iostream>

#include "common/log.h"

namespace arthrosim::common {

std::string format_duration(double seconds) {
  char buf[64];
  if (!std::isfinite(seconds) || seconds < 0) return "?";
  if (seconds < 60.0) {
    std::snprintf(buf, sizeof buf, "%.1f s", seconds);
  } else if (seconds < 3600.0) {
    const long s = std::lround(seconds);
    std::snprintf(buf, sizeof buf, "%ld min %02ld s", s / 60, s % 60);
  } else {
    const long m = std::lround(seconds / 60.0);
    std::snprintf(buf, sizeof buf, "%ld h %02ld min", m / 60, m % 60);
  }
  return buf;
}

Progress::Progress(std::string label, std::int64_t total, ProgressOptions options)
    : label_(std::move(label)), total_(total), options_(std::move(options)) {
  if (!options_.clock) {
    options_.clock = [] {
      return std::chrono::duration<double>(std::chrono::steady_clock::now().time_since_epoch()).count();
    };
  }
  options_.percent_step = std::clamp(options_.percent_step, 1, 100);
  out_ = options_.out != nullptr ? options_.out : &std::cerr;
  mode_ = options_.mode;
  if (mode_ == ProgressOptions::Mode::kAuto) {
    // A caller-supplied stream is never a terminal as far as we know.
    mode_ = options_.out == nullptr && isatty(fileno(stderr)) ? ProgressOptions::Mode::kTty
                                                              : ProgressOptions::Mode::kPlain;
  }
  if (total_ <= 0 || !log_enabled(LogLevel::kInfo)) mode_ = ProgressOptions::Mode::kOff;
  start_ = options_.clock();
  last_print_ = start_;
}

Progress::~Progress() { finish(); }

void Progress::update(std::int64_t done) {
  done_ = std::clamp<std::int64_t>(done, 0, std::max<std::int64_t>(total_, 0));
  if (finished_ || mode_ == ProgressOptions::Mode::kOff) return;
  if (done_ == total_) {
    finish();
    return;
  }
  const double now = options_.clock();
  if (mode_ == ProgressOptions::Mode::kTty) {
    if (now - last_print_ >= options_.tty_interval_s) print_tty(now, false);
    return;
  }
  const int percent = static_cast<int>(100 * done_ / total_);
  const int step = options_.percent_step;
  if (percent / step > last_percent_printed_ / step || now - last_print_ >= options_.plain_interval_s) {
    print_plain(now, false);
  }
}

void Progress::finish() {
  if (finished_) return;
  finished_ = true;
  if (mode_ == ProgressOptions::Mode::kOff) return;
  const double now = options_.clock();
  if (mode_ == ProgressOptions::Mode::kTty) {
    print_tty(now, true);
  } else {
    print_plain(now, true);
  }
}

void Progress::print_plain(double now, bool final_line) {
  const double elapsed = now - start_;
  char buf[256];
  if (final_line) {
    if (done_ == total_) {
      std::snprintf(buf, sizeof buf, "%s: done %lld/%lld in %s\n", label_.c_str(), static_cast<long long>(done_),
                    static_cast<long long>(total_), format_duration(elapsed).c_str());
    } else {
      std::snprintf(buf, sizeof buf, "%s: stopped at %lld/%lld after %s\n", label_.c_str(),
                    static_cast<long long>(done_), static_cast<long long>(total_), format_duration(elapsed).c_str());
    }
  } else {
    const int percent = static_cast<int>(100 * done_ / total_);
    const std::string eta =
        done_ > 0 ? format_duration(elapsed * static_cast<double>(total_ - done_) / static_cast<double>(done_)) : "?";
    std::snprintf(buf, sizeof buf, "%s: %d%% (%lld/%lld) elapsed %s, eta %s\n", label_.c_str(), percent,
                  static_cast<long long>(done_), static_cast<long long>(total_), format_duration(elapsed).c_str(),
                  eta.c_str());
    // Remember the multiple of percent_step reached, so a time-triggered
    // line does not suppress the next percentage line.
    last_percent_printed_ = percent;
  }
  *out_ << buf << std::flush;
  last_print_ = now;
}

void Progress::print_tty(double now, bool final_line) {
  const double elapsed = now - start_;
  constexpr int kWidth = 30;
  const double frac = static_cast<double>(done_) / static_cast<double>(total_);
  const int filled = static_cast<int>(frac * kWidth);
  std::string bar(kWidth, ' ');
  for (int i = 0; i < filled; ++i) bar[i] = '=';
  if (filled < kWidth) bar[filled] = '>';
  const double rate = elapsed > 0 ? static_cast<double>(done_) / elapsed : 0.0;
  const std::string eta = done_ > 0 ? format_duration(elapsed * (1.0 - frac) / frac) : "?";
  char buf[512];
  if (final_line) {
    std::snprintf(buf, sizeof buf, "\r%s [%s] %3d%% %lld/%lld %.3g/s in %s\033[K\n", label_.c_str(), bar.c_str(),
                  static_cast<int>(100 * frac), static_cast<long long>(done_), static_cast<long long>(total_), rate,
                  format_duration(elapsed).c_str());
  } else {
    std::snprintf(buf, sizeof buf, "\r%s [%s] %3d%% %lld/%lld %.3g/s eta %s\033[K", label_.c_str(), bar.c_str(),
                  static_cast<int>(100 * frac), static_cast<long long>(done_), static_cast<long long>(total_), rate,
                  eta.c_str());
  }
  *out_ << buf << std::flush;
  last_print_ = now;
}

}  // namespace arthrosim::common
