// The data a calibration run consists of, independent of where it is stored: IMU frames with the
// table angles sampled at the same instant, temperatures, the site, the mount and the segments.
// Storage, import/export, the simulator and the estimators all exchange these types.
#pragma once

#include <array>
#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "core/table.hpp"
#include "core/units.hpp"

namespace imucal {

// One IMU sample: increments over (t_prev, t] in the sensor axes, already multiplied by the
// nominal scale factors, and the table encoder angles at t (unwrapped, degrees).
struct ImuFrame {
  std::int64_t t_ns = 0;
  Eigen::Vector3d dtheta_rad = Eigen::Vector3d::Zero();
  Eigen::Vector3d dv_mps = Eigen::Vector3d::Zero();
  Eigen::Vector3d table_deg = Eigen::Vector3d::Zero();  // outer, middle, inner
};

// Temperatures at one instant. Held until the next sample (sample-and-hold on the frame clock).
struct TempSample {
  std::int64_t t_ns = 0;
  Eigen::Vector3d gyro_C = Eigen::Vector3d::Constant(25.0);   // FOG coil means, x y z
  Eigen::Vector3d accel_C = Eigen::Vector3d::Constant(25.0);  // accelerometers, x y z
  double chamber_C = 25.0;
  std::optional<double> chamber_setpoint_C;
  // The eight sensors of each FOG coil, [coil x y z][sensor 1..8], when the logger reports them
  // (formats.md: temp_gx_1_C .. temp_gz_8_C); gyro_C is then their mean. They tell a broken
  // sensor from a real change of the coil's temperature.
  std::optional<std::array<std::array<double, 8>, 3>> coil_sensors_C;
};

struct Site {
  double latitude_deg = 59.94;
  double longitude_deg = 30.31;
  double height_m = 10.0;
  std::optional<double> gravity_mps2;  // measured g at the table's axis intersection
  double middle_axis_azimuth_deg = 0.0;
};

struct Mount {
  Eigen::Matrix3d C_o_p = Eigen::Matrix3d::Identity();  // nominal fixture: v_p = C_o_p v_o
  Eigen::Vector3d r0_p_m = Eigen::Vector3d::Zero();     // IMU origin from the axis intersection
};

// A named interval of the motion program. kind: static, rate, sine, coning, tilt, move.
struct SegmentInfo {
  std::string name;
  std::string kind;
  double t0_s = 0.0;
  double t1_s = 0.0;
};

// Everything in meta.json of an imucal-recording/1 bundle, plus what a simulated run adds.
struct RecordingMeta {
  Site site;
  std::string imu_serial = "SIM-0001";
  double rate_hz = 1000.0;
  Mount mount;
  std::vector<SegmentInfo> segments;
  // LSB of the integer counts the IMU delivers; absent for imported CSV (stored as doubles).
  std::optional<double> gyro_lsb_rad;
  std::optional<double> accel_lsb_mps;
  std::string program_json;  // the motion program that made the run, if known (JSON text)
  std::string truth_json;    // the truth imucal-imu-model/1 of a simulated run (JSON text)
  // The table's own errors and their 1-sigma (formats.md `table`); absent: an ideal table.
  std::optional<table::TableCertificate> table;
};

// The table a recording was made on, as every reference computes it: the site's middle-axis
// azimuth and the certificate's geometry when it gives one (the ideal table otherwise).
inline table::TableKinematics table_kinematics(const RecordingMeta& meta) {
  const double azimuth_rad = meta.site.middle_axis_azimuth_deg * units::kDegToRad;
  if (meta.table && meta.table->geometry) return table::TableKinematics(azimuth_rad, *meta.table->geometry);
  return table::TableKinematics(azimuth_rad);
}

}  // namespace imucal
