// Progress lines on stderr for long steps: "ingest: parse 42% 12.3 M/s ETA 8s", at most twice a
// second, overwritten in place on a terminal and one line per update otherwise (logs, CI).
#pragma once

#include <unistd.h>

#include <chrono>
#include <cstdint>
#include <cstdio>
#include <string>

namespace mt {

class Progress {
 public:
  Progress(bool enabled, std::string task, uint64_t total, const char* unit = "tri")
      : enabled_(enabled), task_(std::move(task)), total_(total), unit_(unit), tty_(isatty(2)),
        start_(Clock::now()), last_(start_) {}

  // Cheap enough to call per element: the clock is read once `done` has moved on by 1/4096 of the
  // total since the last reading (a clock read per vertex was 3% of a pass over 27 M of them).
  void update(uint64_t done) {
    if (!enabled_ || done < nextCheck_) return;
    nextCheck_ = done + total_ / 4096;
    auto now = Clock::now();
    if (std::chrono::duration<double>(now - last_).count() < (tty_ ? 0.5 : 5.0)) return;
    last_ = now;
    print(done, false);
  }
  void finish(uint64_t done) {
    if (enabled_) print(done, true);
  }
  double seconds() const { return std::chrono::duration<double>(Clock::now() - start_).count(); }

 private:
  using Clock = std::chrono::steady_clock;
  void print(uint64_t done, bool final) {
    double s = seconds();
    double rate = s > 0 ? double(done) / s : 0;
    char line[256];
    if (final) {
      std::snprintf(line, sizeof line, "%s: %.1f M %s in %.1f s (%.2f M %s/s)", task_.c_str(), double(done) / 1e6, unit_,
                    s, rate / 1e6, unit_);
    } else if (total_ > 0) {
      double pct = 100.0 * double(done) / double(total_);
      double eta = rate > 0 ? double(total_ - std::min(done, total_)) / rate : 0;
      std::snprintf(line, sizeof line, "%s: %5.1f%%  %.2f M %s/s  ETA %.0f s", task_.c_str(), pct, rate / 1e6, unit_, eta);
    } else {
      std::snprintf(line, sizeof line, "%s: %.1f M %s  %.2f M %s/s", task_.c_str(), double(done) / 1e6, unit_, rate / 1e6, unit_);
    }
    std::fprintf(stderr, tty_ ? "\r\033[K%s%s" : "%s%s", line, final || !tty_ ? "\n" : "");
    std::fflush(stderr);
  }
  bool enabled_;
  std::string task_;
  uint64_t total_;
  const char* unit_;
  bool tty_;
  Clock::time_point start_, last_;
  uint64_t nextCheck_ = 0;
};

}  // namespace mt
