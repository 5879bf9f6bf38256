// Small helpers shared by the driver tests: condition polling with a generous deadline (the tests
// run on a loaded two-core machine and under sanitizers), and a stopwatch for bounded-time checks.
#pragma once

#include <chrono>
#include <thread>

namespace imucal::drivers::test {

using namespace std::chrono_literals;

// Polls `pred` until it holds or `timeout` passes; returns its last value.
template <class Pred>
bool eventually(Pred pred, std::chrono::milliseconds timeout = 10s, std::chrono::milliseconds step = 5ms) {
  const auto until = std::chrono::steady_clock::now() + timeout;
  while (!pred()) {
    if (std::chrono::steady_clock::now() > until) return pred();
    std::this_thread::sleep_for(step);
  }
  return true;
}

class Stopwatch {
 public:
  Stopwatch() : t0_(std::chrono::steady_clock::now()) {}
  double seconds() const { return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0_).count(); }

 private:
  std::chrono::steady_clock::time_point t0_;
};

}  // namespace imucal::drivers::test
