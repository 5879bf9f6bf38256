// Speed of the foundation: simulate the navigation program (2 h at 1 kHz, error-free IMU) and
// navigate it, each timed separately, frames per second printed. Not a test: run by hand,
// figures recorded in bench/README.md.
#include <chrono>
#include <cstdio>
#include <vector>

#include "sim/simulator.hpp"
#include "estimators/navigation_run.hpp"

using namespace imucal;
using Clock = std::chrono::steady_clock;

int main(int argc, char** argv) {
  const double duration_s = argc > 1 ? std::atof(argv[1]) : 7200.0;
  const auto program = motion::load_program("navigation", motion::TableLimits{});
  sim::SimConfig cfg;
  cfg.rate_hz = 1000;
  cfg.duration_s = duration_s;
  cfg.mount.r0_p_m << 0.03, -0.02, 0.05;
  sim::Simulator sim(program, ImuModel{}, cfg);
  const RecordingMeta meta = sim.meta();
  // Simulate into memory in chunks and navigate chunk by chunk, timing each side alone.
  std::vector<ImuFrame> chunk(100000);
  double t_sim = 0, t_nav = 0;
  long long frames = 0;
  nav::NavigationRun run(meta, ImuModel{}, 10.0, nullptr);
  for (;;) {
    auto t0 = Clock::now();
    std::size_t n = 0;
    while (n < chunk.size() && sim.next(chunk[n])) ++n;
    auto t1 = Clock::now();
    for (std::size_t i = 0; i < n; ++i) run.push(chunk[i]);
    auto t2 = Clock::now();
    t_sim += std::chrono::duration<double>(t1 - t0).count();
    t_nav += std::chrono::duration<double>(t2 - t1).count();
    frames += static_cast<long long>(n);
    if (n < chunk.size()) break;
  }
  const nav::NavSummary s = run.finish();
  std::printf("{\"frames\": %lld, \"simulate_s\": %.2f, \"simulate_frames_per_s\": %.0f, \"navigate_s\": %.2f, "
              "\"navigate_frames_per_s\": %.0f, \"total_s\": %.2f, \"max_velocity_error_mps\": %.3e, "
              "\"max_position_error_m\": %.3e}\n",
              frames, t_sim, static_cast<double>(frames) / t_sim, t_nav, static_cast<double>(frames) / t_nav,
              t_sim + t_nav, s.max_velocity_error_mps, s.max_position_error_m);
  return 0;
}
