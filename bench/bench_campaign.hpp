// A simulated campaign through all three real drivers against the three simulated devices on
// loopback, at the IMU's full rate: the table runs a cycle of rate, position and oscillation
// segments (watchdog armed, demands repeated as keep-alive), the chamber ramps, the IMU streams.
// Reports lost frames, the table-to-IMU alignment error (IMU sample times against table angles
// interpolated from the table driver's time-coherent reads, compared with the physics truth), and
// the CPU each driver's thread used. `imucal_drivers_bench` runs it for 10 minutes; the driver
// tests run it for a few seconds.
#pragma once

#include <cstdint>
#include <map>
#include <string>

namespace imucal::bench {

struct CampaignOptions {
  double duration_s = 600.0;
  double imu_rate_hz = 1000.0;
  double table_read_hz = 200.0;
  double chamber_read_hz = 1.0;
  bool progress = false;  // one line per 10 s on stderr
};

struct CampaignReport {
  double duration_s = 0.0;
  std::uint64_t imu_samples = 0, imu_lost = 0, imu_gaps = 0, imu_crc_failures = 0, imu_malformed = 0, imu_stalls = 0;
  std::uint64_t imu_errors = 0;          // poll() errors
  std::uint64_t imu_not_sent = 0;        // the simulated IMU could not send (full link)
  std::uint64_t table_reads = 0, table_errors = 0, chamber_reads = 0, chamber_errors = 0;
  std::uint64_t alignment_points = 0;
  std::uint64_t table_clock_resets = 0, imu_clock_resets = 0;  // clock models restarted on a jump
  double alignment_rms_us = 0.0, alignment_p99_us = 0.0, alignment_max_us = 0.0;  // table angle vs IMU sample, as time
  double imu_time_rms_us = 0.0, imu_time_max_us = 0.0;    // IMU sample time vs truth
  double imu_cpu_percent = 0.0, table_cpu_percent = 0.0, chamber_cpu_percent = 0.0;  // of one core
  double process_cpu_percent = 0.0;  // everything: simulated devices and physics included
  std::uint64_t physics_restarts = 0;
  std::map<std::string, std::uint64_t> errors;  // "device: error kind" -> count

  std::string to_text() const;
};

// Throws std::runtime_error when a device cannot be set up.
CampaignReport run_driver_campaign(const CampaignOptions& options);

}  // namespace imucal::bench
