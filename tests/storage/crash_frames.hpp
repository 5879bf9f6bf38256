// The deterministic frame sequence of the crash tests: frame k is a pure function of k, so that a
// writer restarted after kill -9 continues where the run ends and the test can check every frame
// (exactly once, in order, bit for bit) without keeping a copy.
#pragma once

#include <cstdint>

#include "core/recording.hpp"

namespace imucal::test {

inline constexpr double kCrashGyroLsbRad = 1e-11;
inline constexpr double kCrashAccelLsbMps = 1e-10;
inline constexpr std::int64_t kCrashFramePeriodNs = 20'000;  // 50 kHz of data time

inline RecordingMeta crash_meta() {
  RecordingMeta meta;
  meta.imu_serial = "CRASH-1";
  meta.rate_hz = 50'000.0;
  meta.gyro_lsb_rad = kCrashGyroLsbRad;
  meta.accel_lsb_mps = kCrashAccelLsbMps;
  return meta;
}

inline ImuFrame expected_frame(std::int64_t k) {
  ImuFrame f;
  f.t_ns = (k + 1) * kCrashFramePeriodNs;
  // A cheap integer hash of k gives counts that differ from frame to frame.
  std::uint64_t h = static_cast<std::uint64_t>(k) * 0x9E3779B97F4A7C15ULL;
  for (int axis = 0; axis < 3; ++axis) {
    h ^= h >> 29;
    h *= 0xBF58476D1CE4E5B9ULL;
    const auto gyro = static_cast<std::int32_t>(h % 2'000'001) - 1'000'000;
    const auto accel = static_cast<std::int32_t>((h >> 21) % 200'000'001) - 100'000'000;
    f.dtheta_rad(axis) = static_cast<double>(gyro) * kCrashGyroLsbRad;
    f.dv_mps(axis) = static_cast<double>(accel) * kCrashAccelLsbMps;
    f.table_deg(axis) = static_cast<double>(k % 36'000) * 0.01 + 90.0 * axis;
  }
  return f;
}

}  // namespace imucal::test
