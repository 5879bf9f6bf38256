// The simulated world the simulated devices share: one world clock (seconds since the world's
// epoch, an instant of the host time base) and the table's servo with its commanded motion. The
// simulated table answers from it, the simulated IMU senses its motion, so a test or a campaign
// sees one consistent physical setup through three drivers.
#pragma once

#include <cstdint>
#include <mutex>

#include "drivers/interfaces.hpp"
#include "sim/table_servo.hpp"

namespace imucal::sim {

class SimWorld {
 public:
  explicit SimWorld(const ServoConfig& servo, std::int64_t epoch_ns = drivers::host_time_ns())
      : servo_(servo), epoch_ns_(epoch_ns) {}

  std::int64_t epoch_ns() const noexcept { return epoch_ns_; }
  double world_s(std::int64_t host_ns) const noexcept { return static_cast<double>(host_ns - epoch_ns_) * 1e-9; }
  std::int64_t host_ns(double world_s) const noexcept {
    return epoch_ns_ + static_cast<std::int64_t>(world_s * 1e9 + (world_s >= 0 ? 0.5 : -0.5));
  }
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
};

}  // namespace imucal::sim
