// The simulated table's controller: interlock state machine, per-axis modes (off, position, rate,
// synthesis), limits per axis and mode, a track watchdog, limit-hit faults; and the motion it
// commands, kept as analytic pieces (constant, constant-acceleration, sine) so that the IMU
// physics (sim::Simulator over a motion::Program, see program_from()) senses exactly the motion
// the table reports. Pure: times are world seconds passed in by the caller; no clock, no I/O.
//
// Motion rules (docs/drivers.md): position demands are rest-to-rest trapezoids at the mode's rate
// and acceleration limits (a moving axis first brakes); rate demands ramp the rate at the
// acceleration limit; an oscillation starts from rest at a turning point of the requested sine
// (phase referred to world time 0) and stops at its next turning point; interlock open, a limit
// hit or the watchdog brake the axis at once with its off-mode acceleration and switch it off.
#pragma once

#include <array>
#include <cstdint>
#include <limits>
#include <optional>
#include <string>
#include <vector>

#include "drivers/interfaces.hpp"
#include "drivers/table_dialect.hpp"
#include "motion_programs/program.hpp"

namespace imucal::sim {

struct ServoConfig {
  std::array<double, 3> start_deg{};
  // [axis][mode], mode indexed by drivers::TableMode (off, position, rate, synthesis).
  std::array<std::array<drivers::AxisLimitSetting, 4>, 3> limits{};
  double moving_threshold_dps = 1e-6;
};

struct ServoResult {
  drivers::dialect::Refusal refusal = drivers::dialect::Refusal::none;
  std::string text;
  bool ok() const noexcept { return refusal == drivers::dialect::Refusal::none; }
};

struct AxisSample {
  double angle_deg = 0.0;
  double rate_dps = 0.0;
  double accel_dps2 = 0.0;
};

class TableServo {
 public:
  explicit TableServo(const ServoConfig& config);

  // Every command first processes the events (limit hits, watchdog) up to t. Times passed in
  // must not decrease; an earlier time is treated as the latest one seen.
  void advance(double t_s);
  ServoResult interlock_close(double t_s);
  ServoResult interlock_open(double t_s);
  ServoResult interlock_reset(double t_s);
  ServoResult set_mode(double t_s, int axis, drivers::TableMode mode);
  ServoResult demand_position(double t_s, int axis, double angle_deg);
  ServoResult demand_rate(double t_s, int axis, double rate_dps);
  ServoResult demand_oscillation(double t_s, int axis, const drivers::OscillationDemand& d);
  ServoResult set_limit_position(double t_s, int axis, drivers::TableMode mode, double min_deg, double max_deg);
  ServoResult set_limit_rate(double t_s, int axis, drivers::TableMode mode, double rate_dps);
  ServoResult set_limit_accel(double t_s, int axis, drivers::TableMode mode, double accel_dps2);
  ServoResult set_watchdog(double t_s, double period_s);

  // The commanded motion at t (call advance(t) first for events to be applied).
  std::array<AxisSample, 3> sample(double t_s) const;
  drivers::TableStatus status(double t_s) const;
  drivers::InterlockState interlock() const noexcept { return interlock_; }
  const drivers::AxisLimitSetting& limits(int axis, drivers::TableMode mode) const;

  // The motion from t_from on as a program whose time 0 is t_from (pieces for the physics).
  motion::Program program_from(double t_from_s) const;
  // Increments whenever the motion from some time on changes.
  std::uint64_t version() const noexcept { return version_; }
  double processed_s() const noexcept { return now_; }

 private:
  struct Seg {
    double t0;
    motion::AxisFunc f;  // radians
  };
  struct Axis {
    std::vector<Seg> segs;
    drivers::TableMode mode = drivers::TableMode::off;
    bool at_limit = false;
    bool watchdog = false;
    double last_feed_s = 0.0;
    double limit_event_s = std::numeric_limits<double>::infinity();
    double centre_rad = 0.0;  // synthesis centre
  };

  void eval(const Axis& a, double t, double& angle, double& rate, double& accel) const;
  const Seg& active(const Axis& a, double t) const;
  void replace_from(int axis, double t, std::vector<Seg> segs);
  // Stops the axis gracefully from t (a sine at its next turning point, anything else by braking
  // at accel); returns the time it is at rest and the angle, the trajectory ending there in rest.
  std::pair<double, double> graceful_stop(int axis, double t, double accel_radps2);
  void emergency_stop(int axis, double t);
  void update_limit_event(int axis, double t);
  ServoResult check_motion_allowed(int axis, drivers::TableMode needed) const;
  ServoResult bad_axis(int axis) const;
  drivers::AxisLimitSetting& lim(int axis, drivers::TableMode mode);

  ServoConfig config_;
  std::array<Axis, 3> axes_;
  drivers::InterlockState interlock_ = drivers::InterlockState::open;
  double watchdog_period_s_ = 0.0;
  double now_ = 0.0;
  std::uint64_t version_ = 0;
};

}  // namespace imucal::sim
