// A simulated IMU that speaks any IMU link description (drivers/imu_link.hpp): a thread that waits
// for the host's start command (if the description has one; otherwise it streams from the start,
// as a KVH does once powered) and then sends one sample frame per period and the temperature
// messages at a lower rate, encoded by the same codec the driver decodes with, at the world's real
// time. Its end of the link: a SOCK_SEQPACKET socket carrying CAN frame images (socketcan), a
// connected UDP socket (udp) or the master side of a pseudo-terminal (serial). The increments come
// from the physics simulator (sim::Simulator) driven by the table motion of the shared SimWorld,
// so they are what an IMU on that table would sense; its clock has its own offset and drift.
// Fault injection: lost samples, broken checksums, status faults, pauses (stalls), a closed link,
// and on a byte stream a dropped byte, garbage between frames and a jump of the sequence counter.
#pragma once

#include <chrono>
#include <cstdint>
#include <memory>
#include <optional>
#include <vector>

#include <Eigen/Core>

#include "core/imu_model.hpp"
#include "core/recording.hpp"
#include "drivers/can_protocol.hpp"
#include "drivers/imu_link.hpp"
#include "drivers/link_imu.hpp"
#include "sim/sim_world.hpp"

namespace imucal::sim {

struct SimImuConfig {
  // The frames it speaks. Per-unit LSBs are its own (gyro_lsb_rad_at(rate_hz)); a description
  // that fixes them is used as it is.
  drivers::link::ImuLink link = drivers::link::load_imu_link("imucal-can");
  drivers::can::Framing framing = drivers::can::Framing::fd;  // socketcan only
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
  // Sent in the description's identity message (if it has one) when streaming starts and then
  // every identity_period_s; empty: none sent.
  std::string serial;
  double identity_period_s = 1.0;
};

// What the simulator put in one sample, kept for tests and benchmarks.
struct SampleTruth {
  std::uint32_t sequence = 0;
  double world_s = 0.0;           // the sample instant on the world clock
  std::int64_t host_ns = 0;       // the same instant on the host time base
  Eigen::Vector3d table_deg = Eigen::Vector3d::Zero();
  // The increments its frame carries, as the description decodes them (quantised by the LSB or
  // rounded to float32, rates times the period): what the driver must deliver.
  std::array<double, 3> dtheta_rad{};
  std::array<double, 3> dv_mps{};
};

class SimImu {
 public:
  // Takes ownership of link_fd (its end of the link, as the description's transport wants it) and
  // starts the device thread.
  SimImu(SimWorld& world, int link_fd, SimImuConfig config);
  ~SimImu();
  SimImu(const SimImu&) = delete;
  SimImu& operator=(const SimImu&) = delete;

  // The LSB of its integer increments (0 when the description has floats or rates).
  double gyro_lsb_rad() const noexcept;
  double accel_lsb_mps() const noexcept;
  // The scale factors a simulated IMU at this rate uses (an increment's resolution scales with
  // the sample period), known before one exists: what an operator configures for it.
  static double gyro_lsb_rad_at(double rate_hz) noexcept;
  static double accel_lsb_mps_at(double rate_hz) noexcept;
  // What a driver reading this device is configured with: its link (LSBs resolved) and rate.
  drivers::LinkImuConfig driver_config() const;
  bool streaming() const noexcept;
  std::uint64_t samples_sent() const noexcept;
  std::uint64_t samples_not_sent() const noexcept;  // dropped by injection or a full link
  std::uint64_t physics_restarts() const noexcept;  // table motion changes taken in
  // The truth of a recent sample (the last ~60 s are kept); empty when unknown.
  std::optional<SampleTruth> truth(std::uint32_t sequence) const;

  // Faults.
  void drop_next_samples(int count);
  void corrupt_next_samples(int count);  // one bit of the first gyro field, after the checksum
  // Bits flipped against a healthy status (a "valid" bit cleared, or a fault bit set).
  void set_status_bits(std::uint64_t bits);
  void skip_sequence(int count);          // the counter jumps; no sample is missing
  void drop_byte_of_next_sample();        // one byte of the next frame never leaves (streams)
  void drop_byte_of_next_samples(int count);  // the same for each of the next `count` frames
  void send_garbage(std::vector<std::uint8_t> bytes);  // written before the next frame
  // Nothing sent for `duration` from the next frame on (frames already due are sent first); the
  // samples due meanwhile are lost.
  void pause(std::chrono::milliseconds duration);
  std::int64_t pause_began_ns() const;  // host time the last pause began; 0 before any
  void close_link();
  void set_temperature(double celsius);

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace imucal::sim
