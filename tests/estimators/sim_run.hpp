// A built-in program (or a program file) simulated with a truth IMU, every frame pushed into an
// estimator built from the run's metadata: the estimator tests' one way of running a simulation.
#pragma once

#include <cstdint>
#include <memory>
#include <stdexcept>
#include <string>

#include "sim/simulator.hpp"
#include "motion_programs/program.hpp"

namespace imucal::simrun {

// The tests run one program and truth with seed after seed: the motion's signal (sim::MotionSignal,
// most of a simulation's time) is computed by the first run and shared by the next while they
// match; another program or truth computes its own.
inline void share_motion_signal(sim::Simulator& s) {
  static std::shared_ptr<const sim::MotionSignal> last;
  if (last) {
    try {
      s.use_motion_signal(last);
      return;
    } catch (const std::invalid_argument&) {
      // of another run: replaced below
    }
  }
  last = s.motion_signal();
  s.use_motion_signal(last);
}

// Middle axis 15 deg east of north, so that no axis is on a cardinal direction.
template <class Estimator, class Finish>
auto simulate_into(const std::string& program, const ImuModel& truth, double rate_hz, std::uint64_t seed, Finish finish) {
  const motion::Program p = motion::load_program(program, motion::TableLimits{});
  sim::SimConfig cfg;
  cfg.rate_hz = rate_hz;
  cfg.seed = seed;
  cfg.site.middle_axis_azimuth_deg = 15;
  sim::Simulator s(p, truth, cfg);
  share_motion_signal(s);
  Estimator est(s.meta());
  ImuFrame f;
  while (s.next(f)) est.push(f);
  return finish(est);
}

}  // namespace imucal::simrun
