// Speed of stage 3: the whole navigation program at 1 kHz through the 39-state filter, with the
// share spent in the covariance work measured by running the same pass with the covariance
// propagation interval stretched so that it (almost) never runs. Frames come from memory so the
// simulator is not timed.
#include <chrono>
#include <cstdio>
#include <vector>

#include "sim/simulator.hpp"
#include "estimators/nav_filter.hpp"

using namespace imucal;
using Clock = std::chrono::steady_clock;

int main(int argc, char** argv) {
  const double rate_hz = argc > 1 ? std::atof(argv[1]) : 1000.0;
  const auto program = motion::load_program("navigation", motion::TableLimits{});
  sim::SimConfig cfg;
  cfg.rate_hz = rate_hz;
  cfg.mount.r0_p_m << 0.03, -0.02, 0.05;
  ImuModel truth;
  truth.gyro.noise.arw_rad_rts = 0.0005 / 60.0 * 3.14159265358979 / 180.0;
  truth.accel.noise.vrw_mps_rts = 0.002 / 60.0;
  sim::Simulator sim(program, truth, cfg);
  const RecordingMeta meta = sim.meta();
  std::vector<ImuFrame> frames;
  frames.reserve(static_cast<std::size_t>(sim.frame_count()));
  ImuFrame f;
  while (sim.next(f)) frames.push_back(f);
  auto run = [&](const navfilter::Options& opt) {
    const auto t0 = Clock::now();
    navfilter::NavCalibrationFilter filter(meta, truth, opt);
    for (const ImuFrame& fr : frames) filter.push(fr);
    const navfilter::Result r = filter.finish();
    return std::make_pair(std::chrono::duration<double>(Clock::now() - t0).count(), r);
  };
  const auto [full_s, r] = run(navfilter::Options{});
  navfilter::Options sparse;
  sparse.propagate_interval_s = 1e9;  // covariance work skipped: what remains is the per-frame work
  sparse.update_interval_s = 1e9;
  const auto [frame_only_s, r2] = run(sparse);
  (void)r2;
  std::printf("{\"frames\": %zu, \"rate_hz\": %.0f, \"filter_s\": %.2f, \"frames_per_s\": %.0f, "
              "\"covariance_steps\": %lld, \"covariance_share\": %.2f, \"status\": \"%s\"}\n",
              frames.size(), rate_hz, full_s, static_cast<double>(frames.size()) / full_s,
              static_cast<long long>(r.covariance_steps), (full_s - frame_only_s) / full_s, r.status.c_str());
  return 0;
}
