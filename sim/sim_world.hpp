// The simulated world the simulated devices share: one world clock (seconds since the world's
// epoch, an instant of the host time base) and the table's servo with its commanded motion. The
// simulated table answers from it, the simulated IMU senses its motion, so a test or a campaign
// sees one consistent physical setup through three drivers.
//
// Accelerated: with a time scale k the world's physics (motion, samples, chamber air) run k world
// seconds per host second, but the devices' hardware clocks (the time tags of table replies and
// IMU samples, clock_s()) still tick at the host's rate. The drivers map those tags to the host
// time base with a clock model that can only follow a clock near the host's rate; the bench maps
// host time back to world time with k.
#pragma once

#include <cstdint>
#include <mutex>

#include "drivers/interfaces.hpp"
#include "sim/table_servo.hpp"

namespace imucal::sim {

class SimWorld {
 public:
  explicit SimWorld(const ServoConfig& servo, std::int64_t epoch_ns = drivers::host_time_ns(), double time_scale = 1.0)
      : servo_(servo), epoch_ns_(epoch_ns), time_scale_(time_scale) {}

  std::int64_t epoch_ns() const noexcept { return epoch_ns_; }
  double time_scale() const noexcept { return time_scale_; }  // world seconds per host second
  double world_s(std::int64_t host_ns) const noexcept {
    return static_cast<double>(host_ns - epoch_ns_) * 1e-9 * time_scale_;
  }
  std::int64_t host_ns(double world_s) const noexcept {
    const double host_s = world_s / time_scale_;
    return epoch_ns_ + static_cast<std::int64_t>(host_s * 1e9 + (host_s >= 0 ? 0.5 : -0.5));
  }
  // A device clock's reading (seconds since the epoch, before the device's own drift and offset)
  // at world time world_s: host seconds.
  double clock_s(double world_s) const noexcept { return world_s / time_scale_; }
  double now_s() const noexcept { return world_s(drivers::host_time_ns()); }

  // f(TableServo&, double t_now) under the world lock, events processed up to now.
  template <class F>
  decltype(auto) with_servo(F&& f) {
    std::lock_guard lock(mutex_);
    const double t = now_s();
    servo_.advance(t);
    return f(servo_, servo_.processed_s());
  }

 private:
  std::mutex mutex_;
  TableServo servo_;
  std::int64_t epoch_ns_;
  double time_scale_;
};

}  // namespace imucal::sim
