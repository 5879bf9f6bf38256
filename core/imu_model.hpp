// The sensor error model of CONVENTIONS.md (seed eq. 1): biases, scale factors (+/- for gyros),
// the six misalignment angles per triad in the seed's sign convention, accelerometer proof-mass
// lever arms, per-channel delays, noise, the optional nonlinear terms (gyro scale nonlinearity,
// accelerometer K2/K3, gyro g-sensitivity); and its imucal-imu-model/1 JSON form.
// Everything here is SI (rad, rad/s, m/s^2, m, s, dimensionless scale); JSON carries the units.
#pragma once

#include <array>
#include <map>
#include <optional>
#include <string>

#include <Eigen/Core>

#include "core/units.hpp"

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

// The rate unit of the gyro scale nonlinearity: q = |w_j| / (100 deg/s) (CONVENTIONS.md).
inline constexpr double kGyroNonlinearityRate_radps = 100.0 * units::kDegToRad;

struct GyroErrors {
  Eigen::Vector3d bias_radps = Eigen::Vector3d::Zero();
  Eigen::Vector3d scale_pos = Eigen::Vector3d::Zero();  // dimensionless (ppm * 1e-6)
  Eigen::Vector3d scale_neg = Eigen::Vector3d::Zero();
  Misalignment misalignment_rad;
  Eigen::Vector3d delay_s = Eigen::Vector3d::Zero();
  GyroNoise noise;
  // Scale-factor nonlinearity: row j holds c1, c2, c3 of gyro j, dimensionless (ppm * 1e-6); its
  // scale error gains c1 q + c2 q^2 + c3 q^3, q = |w_j| / kGyroNonlinearityRate_radps.
  Eigen::Matrix3d scale_nonlinear = Eigen::Matrix3d::Zero();
  // g-sensitivity: gyro j's bias gains row j . f_origin_o / g_std, in rad/s per g (rows gyro x y z,
  // columns the specific force at the origin along o x y z).
  Eigen::Matrix3d g_sensitivity_radps_per_g = Eigen::Matrix3d::Zero();
};

struct AccelErrors {
  Eigen::Vector3d bias_mps2 = Eigen::Vector3d::Zero();
  Eigen::Vector3d scale = Eigen::Vector3d::Zero();
  Misalignment misalignment_rad;
  Eigen::Vector3d lever_arm_y_m = Eigen::Vector3d::Zero();  // y proof mass from the x proof mass, o
  Eigen::Vector3d lever_arm_z_m = Eigen::Vector3d::Zero();
  Eigen::Vector3d delay_s = Eigen::Vector3d::Zero();
  AccelNoise noise;
  // IEEE Std 1293's K2 and K3 as scale-error slopes: channel j's scale error gains
  // k2_per_g[j] a + k3_per_g2[j] a^2 with a = f_j[j] / g_std (its own proof mass's specific force
  // along its axis, in g). Its output then gains (k2 a^2 + k3 a^3) g_std, so K2 [ug/g^2] =
  // k2_per_g * 1e6 and K3 [ug/g^3] = k3_per_g2 * 1e6 under either reading of the JSON's
  // k2_ug_per_g2 / k3_ug_per_g3 (scale-error slope or output per g^2).
  Eigen::Vector3d k2_per_g = Eigen::Vector3d::Zero();
  Eigen::Vector3d k3_per_g2 = Eigen::Vector3d::Zero();
};

// True when the accelerometers have K2 or K3 (their inverse model then iterates).
bool has_nonlinear_terms(const AccelErrors& a);

// The scale errors s_j of seed eq. 1's S(i), each at its channel's own input (CONVENTIONS.md,
// "Nonlinear terms"): the gyros' by the sign and size of w_io_o[j]; the accelerometers' by
// f_own[j] = f_j[j], the specific force at proof mass j along axis j.
Eigen::Vector3d gyro_scale_errors(const GyroErrors& g, const Eigen::Vector3d& w_io_o_radps);
Eigen::Vector3d accel_scale_errors(const AccelErrors& a, const Eigen::Vector3d& f_own_mps2);
// What g-sensitivity adds to the gyro outputs, rad/s, for the specific force at the origin.
Eigen::Vector3d gyro_g_sensitivity_radps(const GyroErrors& g, const Eigen::Vector3d& f_origin_o_mps2);

struct ImuErrorSet {
  GyroErrors gyro;
  AccelErrors accel;
};

struct ImuModel {
  std::string frame = "instrument";  // "instrument" or "body"
  GyroErrors gyro;
  AccelErrors accel;
  std::optional<ImuErrorSet> sigma;                  // 1-sigma of a calibration result
  // The uncertainty budget behind `sigma` (formats: `budget`): source -> that source's standard
  // uncertainty contribution to each coefficient, in the fields of `sigma` ("type_a": the
  // estimator's own; "table.outer_tilt_arcsec", "site.gravity_mps2", "start_model.accel.k2_ug_per_g2"
  // ...: type B, each from its sensitivity). A coefficient's sigma is the root-sum-square of its
  // entries over the sources; a coefficient no source lists has no budget. Empty: none stated.
  std::map<std::string, ImuErrorSet> budget;
  std::optional<Eigen::Vector3d> body_to_instrument_rad;  // frame "body" only
  std::optional<Eigen::Vector3d> mount_r0_p_m;       // from the lever-arm stage
  std::string thermal_json;                          // the thermal section, kept verbatim for now
  std::string extra_json;                            // keys other stages added (e.g. "status")
};

// Forward model of one triad sample: u = D S(i) i (+ bias and g-sensitivity added by the caller),
// S with the nonlinear terms at the input; the accelerometers' without proof-mass offsets
// (f_j = f_o for every j; the simulator adds the size effect).
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

// Inverse model (seed eq. 2) applied to increments over dt_s: i = S^-1 D^-1 (u - u0 dt).
// Gyro scale is chosen by the sign of the corrected increment on each axis. With nonlinear terms S
// depends on the input it is solving for: a short fixed-point iteration (imu_model.cpp says why
// three steps reach double precision); without them the first pass is the answer, as before.
//
// Gyros: f_origin_o_mps2 is the specific force at the origin over the same interval (the
// compensated accelerometer output), for the g-sensitivity. The three-argument form does not remove
// the g-sensitivity: for a model without it, or for rates where its few 1e-8 rad/s do not matter.
Eigen::Vector3d compensate_gyro_increment(const GyroErrors& g, const Eigen::Vector3d& dtheta_rad,
                                          double dt_s, const Eigen::Vector3d& f_origin_o_mps2);
Eigen::Vector3d compensate_gyro_increment(const GyroErrors& g, const Eigen::Vector3d& dtheta_rad,
                                          double dt_s);
// Accelerometers: the specific-force increment at the origin. size_effect_mps2 (rows j:
// f_j - f_origin over the interval, see size_effect_mps2()) is removed in sensor space: channel j's
// raw output is row j of D S applied to f_origin + row j, so subtracting row j of D S times its
// own term and then inverting D S is exact, where seed eq. 7 (removing the terms after the
// inverse) leaves misalignment and scale errors times the size effect. The three-argument form is
// for a model without proof-mass offsets.
Eigen::Vector3d compensate_accel_increment(const AccelErrors& a, const Eigen::Vector3d& dv_mps, double dt_s,
                                           const Eigen::Matrix3d& size_effect_mps2);
Eigen::Vector3d compensate_accel_increment(const AccelErrors& a, const Eigen::Vector3d& dv_mps,
                                           double dt_s);

// The one rule for a sample of both triads (every consumer reaches it through nav::Compensator):
// the accelerometers first, then the gyros with the g-sensitivity of the specific force at the
// origin the accelerometers gave. Inputs are each channel's raw increment on its input's interval.
struct CompensatedIncrements {
  Eigen::Vector3d dtheta_rad = Eigen::Vector3d::Zero();
  Eigen::Vector3d dv_mps = Eigen::Vector3d::Zero();  // at the origin
};
CompensatedIncrements compensate_imu_increments(const GyroErrors& g, const AccelErrors& a,
                                                const Eigen::Vector3d& dtheta_rad, const Eigen::Vector3d& dv_mps,
                                                double dt_s, const Eigen::Matrix3d& size_effect_mps2);

// imucal-imu-model/1. Parsing throws std::runtime_error naming the offending key.
ImuModel imu_model_from_json_text(const std::string& text, const std::string& source_name);
ImuModel read_imu_model_file(const std::string& path);
std::string imu_model_to_json_text(const ImuModel& model);
void write_imu_model_file(const ImuModel& model, const std::string& path);

}  // namespace imucal
