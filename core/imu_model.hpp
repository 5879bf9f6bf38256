// The sensor error model of CONVENTIONS.md (seed eq. 1): biases, scale factors (+/- for gyros),
// the six misalignment angles per triad in the seed's sign convention, accelerometer proof-mass
// lever arms, per-channel delays, noise; and its imucal-imu-model/1 JSON form.
// Everything here is SI (rad, rad/s, m/s^2, m, s, dimensionless scale); JSON carries the units.
#pragma once

#include <array>
#include <optional>
#include <string>

#include <Eigen/Core>

namespace imucal {

// Misalignment "ab": right-handed rotation of sensor axis a about instrument axis b, radians.
struct Misalignment {
  double xy = 0, xz = 0, yx = 0, yz = 0, zx = 0, zy = 0;
};

// The six angles in the order formats.md lists them, each with its JSON key: one table for every
// loop over the angles (parsing, writing, filter states, thermal fits, comparisons).
struct MisalignmentKey {
  const char* name;
  double Misalignment::*member;
};
inline constexpr std::array<MisalignmentKey, 6> kMisalignmentKeys = {{{"xy", &Misalignment::xy},
                                                                     {"xz", &Misalignment::xz},
                                                                     {"yx", &Misalignment::yx},
                                                                     {"yz", &Misalignment::yz},
                                                                     {"zx", &Misalignment::zx},
                                                                     {"zy", &Misalignment::zy}}};

// D (rows are the sensor axes in o, first order):
//   | 1    xz  -xy |
//   | -yz  1   yx  |
//   | zy  -zx  1   |
Eigen::Matrix3d misalignment_matrix(const Misalignment& m);

struct GyroNoise {
  double arw_rad_rts = 0;              // angle random walk, rad/sqrt(s)
  double bias_instability_radps = 0;   // flicker floor of the Allan deviation
  double bias_corr_time_s = 0;         // correlation time of the simulated bias (0 = default)
  double rate_random_walk_radps_rts = 0;  // Wiener-process bias drift, (rad/s)/sqrt(s)
};

struct AccelNoise {
  double vrw_mps_rts = 0;                // velocity random walk, (m/s)/sqrt(s)
  double bias_instability_mps2 = 0;
  double bias_corr_time_s = 0;
  double accel_random_walk_mps2_rts = 0;  // Wiener-process bias drift, (m/s^2)/sqrt(s)
};

struct GyroErrors {
  Eigen::Vector3d bias_radps = Eigen::Vector3d::Zero();
  Eigen::Vector3d scale_pos = Eigen::Vector3d::Zero();  // dimensionless (ppm * 1e-6)
  Eigen::Vector3d scale_neg = Eigen::Vector3d::Zero();
  Misalignment misalignment_rad;
  Eigen::Vector3d delay_s = Eigen::Vector3d::Zero();
  GyroNoise noise;
};

struct AccelErrors {
  Eigen::Vector3d bias_mps2 = Eigen::Vector3d::Zero();
  Eigen::Vector3d scale = Eigen::Vector3d::Zero();
  Misalignment misalignment_rad;
  Eigen::Vector3d lever_arm_y_m = Eigen::Vector3d::Zero();  // y proof mass from the x proof mass, o
  Eigen::Vector3d lever_arm_z_m = Eigen::Vector3d::Zero();
  Eigen::Vector3d delay_s = Eigen::Vector3d::Zero();
  AccelNoise noise;
};

struct ImuErrorSet {
  GyroErrors gyro;
  AccelErrors accel;
};

struct ImuModel {
  std::string frame = "instrument";  // "instrument" or "body"
  GyroErrors gyro;
  AccelErrors accel;
  std::optional<ImuErrorSet> sigma;                  // 1-sigma of a calibration result
  std::optional<Eigen::Vector3d> body_to_instrument_rad;  // frame "body" only
  std::optional<Eigen::Vector3d> mount_r0_p_m;       // from the lever-arm stage
  std::string thermal_json;                          // the thermal section, kept verbatim for now
  std::string extra_json;                            // keys other stages added (e.g. "status")
};

// Forward model of one triad sample: u = D S(i) i (+ bias added by the caller).
Eigen::Vector3d apply_gyro_scale_misalignment(const GyroErrors& g, const Eigen::Vector3d& w_io_o);
Eigen::Vector3d apply_accel_scale_misalignment(const AccelErrors& a, const Eigen::Vector3d& f_o);

// The body frame in the instrument frame, v_o = C_b_o v_b, from a model's
// body_to_instrument rotation vector (formats.md: v_b = (I - [r x]) v_o to first order).
Eigen::Matrix3d C_b_o_of(const Eigen::Vector3d& body_to_instrument_rad);

// Size effect (seed eq. 3): accelerometer j senses the specific force at its own proof mass,
// f_j = f_origin + w x (w x r_j) + dw/dt x r_j (r_x = 0: the origin is the x proof mass).
// The proof-mass offsets of a model resolved in the model's frame, as columns x (zero), y, z: the
// model keeps them in the instrument frame o (formats.md); a body-frame model turns them into b.
Eigen::Matrix3d proof_mass_offsets_m(const ImuModel& model);
// Rows j: f_j - f_origin for the rate w and its derivative dw, in the frame of the offsets.
Eigen::Matrix3d size_effect_mps2(const Eigen::Matrix3d& offsets_m, const Eigen::Vector3d& w_radps,
                                 const Eigen::Vector3d& dw_radps2);
// What the size effect adds to the accelerometer outputs before the bias: channel j is row j of
// D S applied to its own term (row j of size_effect), so removing this from the raw output and
// then inverting D S is exact, where seed eq. 7 (removing the terms after the inverse) leaves
// misalignment and scale errors times the size effect.
Eigen::Vector3d accel_size_effect_output(const AccelErrors& a, const Eigen::Matrix3d& size_effect_mps2);

// Inverse model (seed eq. 2) applied to increments over dt_s: i = S^-1 D^-1 (u - u0 dt).
// Gyro scale is chosen by the sign of the corrected increment on each axis.
Eigen::Vector3d compensate_gyro_increment(const GyroErrors& g, const Eigen::Vector3d& dtheta_rad,
                                          double dt_s);
Eigen::Vector3d compensate_accel_increment(const AccelErrors& a, const Eigen::Vector3d& dv_mps,
                                           double dt_s);

// imucal-imu-model/1. Parsing throws std::runtime_error naming the offending key.
ImuModel imu_model_from_json_text(const std::string& text, const std::string& source_name);
ImuModel read_imu_model_file(const std::string& path);
std::string imu_model_to_json_text(const ImuModel& model);
void write_imu_model_file(const ImuModel& model, const std::string& path);

}  // namespace imucal
