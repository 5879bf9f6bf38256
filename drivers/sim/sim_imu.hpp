// A simulated IMU on a CAN link: a thread that waits for the host's start command and then sends
// one sample record per period (CAN FD, or the classic fallback) and the temperature record at a
// lower rate, on one end of a socket pair, at the world's real time. The increments come from
// the physics simulator (sim::Simulator) driven by the table motion of the shared SimWorld, so
// they are what an IMU on that table would sense; its clock has its own offset and drift.
// Fault injection: lost samples, broken CRCs, status faults, pauses (stalls), a closed link.
#pragma once

#include <chrono>
#include <cstdint>
#include <memory>
#include <optional>

#include <Eigen/Core>

#include "core/imu_model.hpp"
#include "core/recording.hpp"
#include "drivers/can_protocol.hpp"
#include "drivers/sim/sim_world.hpp"

namespace imucal::drivers::sim {

struct SimImuConfig {
  can::Framing framing = can::Framing::fd;
  double rate_hz = 1000.0;
  std::uint64_t seed = 1;
  ImuModel truth;  // instrument frame (see sim::Simulator)
  Site site;
  Mount mount;
  double latency_us = 250.0;        // sample instant to transmission
  double clock_drift_ppm = 0.0;     // the IMU clock against the world clock
  std::int64_t clock_offset_ns = 0;
  double temp_rate_hz = 10.0;
  double temperature_C = 25.0;
};

// What the simulator put in one sample, kept for tests and benchmarks.
struct SampleTruth {
  std::uint32_t sequence = 0;
  double world_s = 0.0;           // the sample instant on the world clock
  std::int64_t host_ns = 0;       // the same instant on the host time base
  Eigen::Vector3d table_deg = Eigen::Vector3d::Zero();
  std::array<std::int32_t, 3> gyro_counts{};
  std::array<std::int32_t, 3> accel_counts{};
};

class SimImu {
 public:
  // Takes ownership of socket_fd (its end of the link) and starts the device thread.
  SimImu(SimWorld& world, int socket_fd, SimImuConfig config);
  ~SimImu();
  SimImu(const SimImu&) = delete;
  SimImu& operator=(const SimImu&) = delete;

  double gyro_lsb_rad() const noexcept;
  double accel_lsb_mps() const noexcept;
  // The scale factors a simulated IMU at this rate uses (an increment's resolution scales with
  // the sample period), known before one exists: what an operator configures for it.
  static double gyro_lsb_rad_at(double rate_hz) noexcept;
  static double accel_lsb_mps_at(double rate_hz) noexcept;
  bool streaming() const noexcept;
  std::uint64_t samples_sent() const noexcept;
  std::uint64_t samples_not_sent() const noexcept;  // dropped by injection or a full link
  std::uint64_t physics_restarts() const noexcept;  // table motion changes taken in
  // The truth of a recent sample (the last ~60 s are kept); empty when unknown.
  std::optional<SampleTruth> truth(std::uint32_t sequence) const;

  // Faults.
  void drop_next_samples(int count);
  void corrupt_next_samples(int count);
  void set_status_bits(std::uint16_t bits);
  void pause(std::chrono::milliseconds duration);  // nothing sent; samples due meanwhile are lost
  void close_link();
  void set_temperature(double celsius);

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace imucal::drivers::sim
