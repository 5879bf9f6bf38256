// Progress on stderr for the long commands (simulate, navigate, calibrate).
#pragma once

#include <chrono>
#include <cstdint>
#include <cstdio>
#include <string>

namespace imucal::cli {

using Clock = std::chrono::steady_clock;

inline double seconds_since(Clock::time_point t0) { return std::chrono::duration<double>(Clock::now() - t0).count(); }

// At most every few percent, so long runs show they are alive.
class Progress {
 public:
  Progress(std::string what, std::int64_t total) : what_(std::move(what)), total_(total) {}
  void update(std::int64_t done) {
    if (total_ <= 0) return;
    const int pct = static_cast<int>(100 * done / total_);
    if (pct >= next_) {
      std::fprintf(stderr, "\r%s: %3d %%", what_.c_str(), pct);
      std::fflush(stderr);
      next_ = pct + 5;
    }
  }
  void done() { std::fprintf(stderr, "\r%s: 100 %%\n", what_.c_str()); }

 private:
  std::string what_;
  std::int64_t total_;
  int next_ = 0;
};

}  // namespace imucal::cli
