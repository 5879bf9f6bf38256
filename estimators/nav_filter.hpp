// Stage 3 of the method (seed ch. 4): refinement of the IMU model by the navigation solution.
// Free-inertial navigation on the table with the current model; the velocity and position of the
// IMU origin are compared with what the table implies (eq. 14) and a 39-state Kalman filter
// (eq. 15) estimates the navigation errors and the residual model errors, which are fed back into
// the model and the navigation at every update. Works in the body frame (accelerometer axes).
// Pure: frames in, model out; the same object runs online (one pass) and offline.
#pragma once

#include <array>
#include <cstdint>
#include <deque>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "core/imu_model.hpp"
#include "core/recording.hpp"
#include "estimators/navigation_run.hpp"
#include "estimators/strapdown.hpp"

namespace imucal::navfilter {

// Named blocks of the error state, PX4-style: nobody writes P(10, 10).
struct Block {
  int index, size;
  const char* name;
};
namespace state {
inline constexpr Block kAttitude{0, 3, "attitude_rad"};
inline constexpr Block kVelocity{3, 3, "velocity_mps"};
inline constexpr Block kPosition{6, 3, "position_m"};
inline constexpr Block kGyroBias{9, 3, "gyro_bias_radps"};
inline constexpr Block kAccelBias{12, 3, "accel_bias_mps2"};
inline constexpr Block kGyroScalePos{15, 3, "gyro_scale_pos"};
inline constexpr Block kGyroScaleNeg{18, 3, "gyro_scale_neg"};
inline constexpr Block kAccelScale{21, 3, "accel_scale"};
inline constexpr Block kGyroAngles{24, 6, "gyro_misalignment_rad"};   // xy xz yx yz zx zy
inline constexpr Block kAccelAngles{30, 3, "accel_misalignment_rad"}; // yz zx zy (x is the reference)
inline constexpr Block kGyroDelay{33, 3, "gyro_delay_s"};
inline constexpr Block kAccelDelay{36, 3, "accel_delay_s"};
// Beyond the seed's 39: the y and z proof-mass offsets (body frame). The lever-arm stage leaves
// them known to ~0.1 mm, and 0.1 mm is 1e-4 m/s^2 during a fast oscillation (1 rad/s): far more
// than the accelerometer errors stage 3 is after (docs/stage3.md).
inline constexpr Block kLeverArmY{39, 3, "accel_lever_arm_y_m"};
inline constexpr Block kLeverArmZ{42, 3, "accel_lever_arm_z_m"};
// How the body frame sits on the platform (the body_to_instrument rotation, the nominal mount
// being exact by convention): what the table's attitude measurement needs beside the gyro delays.
inline constexpr Block kBodyAlignment{45, 3, "body_alignment_rad"};
inline constexpr int kSize = 48;
inline constexpr int kFirstCalibration = 9;  // the calibration states follow the 9 navigation states
inline constexpr int kCalibrationSize = kSize - kFirstCalibration;
inline constexpr std::array<Block, 15> kAll = {kAttitude,     kVelocity,     kPosition,   kGyroBias,   kAccelBias,
                                               kGyroScalePos, kGyroScaleNeg, kAccelScale, kGyroAngles, kAccelAngles,
                                               kGyroDelay,    kAccelDelay,   kLeverArmY,  kLeverArmZ,  kBodyAlignment};
}  // namespace state

using StateVector = Eigen::Matrix<double, state::kSize, 1>;
using StateMatrix = Eigen::Matrix<double, state::kSize, state::kSize>;

// Stage 3's accuracy limits: three times the seed's 1-sigma figures (method.md, ch. 4), body frame.
struct Limits {
  double gyro_bias_dph = 0.003;
  double gyro_scale_ppm = 1.5;      // scale_pos_ppm and scale_neg_ppm
  double gyro_angle_arcsec = 0.3;   // misalignment_arcsec
  double gyro_delay_us = 3.0;
  double accel_bias_mps2 = 1.5e-5;
  double accel_scale_ppm = 0.9;
  double accel_angle_arcsec = 0.9;  // yz zx zy (x and the x-y plane are the body axes)
  double accel_delay_us = 50.0;
};

struct Options {
  double propagate_interval_s = 0.1;  // covariance propagation
  double update_interval_s = 1.0;     // velocity and position measurements
  double velocity_noise_mps = 1e-4;   // 1-sigma of the table reference
  double position_noise_m = 1e-3;
  // 1-sigma of the attitude the table's encoders give (encoder accuracy, axis wobble and
  // orthogonality together; 0 = no attitude measurement). It is what sees the gyros' delay
  // against the table's time base: a lag tau turns the attitude by tau w (docs/stage3.md).
  double attitude_noise_rad = 2.0 * 4.84813681109536e-6;
  double gate_sigma = 5.0;            // innovations beyond this many sigma are rejected
  int divergence_rejections = 20;     // this many consecutive rejections end the run as diverged
  double max_delay_s = 0.01;          // the largest delay the compensation window can follow
  double history_interval_s = 10.0;   // estimate history kept for convergence plots
  double restart_static_s = 25.0;     // statics at least this long restart the navigation (program parts)
  // Initial 1-sigma (seed ch. 4) and process noise.
  double sigma_attitude_rad = 5.0 * 4.84813681109536e-6;
  double sigma_velocity_mps = 1e-4, sigma_position_m = 1e-3;
  double sigma_gyro_bias_radps = 0.01 * 4.84813681109536e-6;  // 0.01 deg/h
  double sigma_accel_bias_mps2 = 1e-3;
  double sigma_gyro_scale = 1e-5, sigma_accel_scale = 1e-5;     // 0.001 %
  double sigma_gyro_angle_rad = 3.0 * 4.84813681109536e-6;      // 3"
  double sigma_accel_angle_rad = 3.0 * 4.84813681109536e-6;
  double sigma_gyro_delay_s = 20e-6, sigma_accel_delay_s = 3e-3;
  // Proof-mass offsets: the model's own sigma when it carries one (the lever-arm stage writes it),
  // never below this; this alone when it does not.
  double sigma_lever_arm_m = 0.3e-3;
  // The body frame on the platform: the model's sigma of the accelerometer angles xy xz yx when it
  // carries one (stage 1), never below this; this alone when it does not.
  double sigma_body_alignment_rad = 3.0 * 4.84813681109536e-6;
  // The type B sources (issue 34), as Schmidt "consider" parameters: each error of the table the
  // recording's certificate gives a 1-sigma for (table.sigma: direct::reference_perturbations,
  // stage 1's list) and the site's g. The filter does not estimate them; it carries their
  // correlation with the state, so that their share of the attitude measurement's error and of
  // the vertical channel is weighed (its gain and gate know that a table's error is the same
  // each time the table stands at the same angles) and is part of the stated sigma, by source in
  // the model's budget. false: the noise alone (an ideal table and a known g assumed).
  bool type_b = true;
  // The site's g's standard uncertainty, m/s^2; absent: earth::site_gravity_sigma_mps2 of the site.
  std::optional<double> gravity_sigma_mps2;
  double gyro_bias_rw_radps_rts = 0.0;   // 0: from the model's noise, else this
  double accel_bias_rw_mps2_rts = 0.0;
  double scale_rw_rts = 1e-9;
};

struct MeasurementRecord {
  static constexpr int kCount = 9;
  double t_s;
  // dv_E, dv_N, dv_U (m/s), dp_E, dp_N, dp_U (m), attitude E, N, U (rad; zero when not measured)
  std::array<double, kCount> innovation;
  std::array<double, kCount> variance;
  std::array<double, kCount> test_ratio;  // innovation^2 / (gate^2 variance): > 1 is rejected
  std::array<bool, kCount> accepted;
};

struct HistoryRecord {
  double t_s;
  StateVector value;  // calibration states as model values (SI), navigation states as errors
  StateVector sigma;
};

struct Result {
  ImuModel model;  // body frame, with sigma
  bool converged = true;
  std::string status;  // "converged" or what went wrong and when
  StateVector sigma0, sigma_final;
  Eigen::Matrix<double, state::kCalibrationSize, state::kCalibrationSize> P_calibration;  // of the calibration states
  StateVector model_values;  // calibration states' final values in the layout of the error state
  std::int64_t updates = 0, rejected = 0, restarts = 0, frames = 0;
  double covariance_time_s = 0;  // wall-clock share is measured by the caller; this counts steps
  std::int64_t covariance_steps = 0;
  std::vector<MeasurementRecord> measurements;
  std::vector<HistoryRecord> history;
  std::vector<double> restart_times_s;  // program time of each restart of the navigation
  // Gyro delays of y and z relative to gyro x, and their sigmas (seed: tau_yx, tau_zx).
  double tau_yx_s = 0, tau_zx_s = 0, sigma_tau_yx_s = 0, sigma_tau_zx_s = 0;
  std::string history_json() const;
};

// What the filter knows so far, for a live display while the frames come (cheap: no history copied).
struct Progress {
  ImuModel model;      // body frame, with the current sigma
  std::string status;  // "running", "rejecting: ..." or "not converged: ..." (then it has stopped)
  double t_s = 0;      // program time of the last frame processed
  std::int64_t frames = 0, updates = 0, rejected = 0, restarts = 0;
  std::vector<double> restart_times_s;
  std::optional<MeasurementRecord> last_measurement;
  double gate_sigma = 0;  // the gate of the innovations, in their sigmas
  StateVector sigma0, sigma;
};

// Calibration-state values of a model in the filter's layout (for tests and NEES).
StateVector model_to_state(const ImuModel& body_model);

class NavCalibrationFilter {
 public:
  // model: the stage-1 model (instrument or body frame; converted to body).
  NavCalibrationFilter(const RecordingMeta& meta, const ImuModel& model, const Options& options = {});
  ~NavCalibrationFilter();
  void push(const ImuFrame& frame);
  // Temperatures for a model with a "thermal" section (ignored without one): push each sample
  // before the frames after it. The compensation then uses the coefficients moved to the
  // temperatures and rates (stage 2); the filter estimates and feeds back the constants at T_ref,
  // which is what the result's model carries beside the unchanged section.
  void push_temp(const TempSample& temp);
  Progress progress() const;
  Result finish();

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

// Offline: several passes over a recording, each seeded with the previous pass's model. `temps`
// (time order) drive the model's thermal compensation, if it has a section.
template <class ForEachFrame>
Result calibrate_offline(const RecordingMeta& meta, const ImuModel& model, ForEachFrame for_each_frame, int passes,
                         const Options& options = {}, const std::vector<TempSample>& temps = {}) {
  ImuModel current = model;
  Result r;
  for (int pass = 0; pass < passes; ++pass) {
    NavCalibrationFilter filter(meta, current, options);
    std::size_t next_temp = 0;
    for_each_frame([&](const ImuFrame& f) {
      while (next_temp < temps.size() && temps[next_temp].t_ns <= f.t_ns) filter.push_temp(temps[next_temp++]);
      filter.push(f);
    });
    r = filter.finish();
    if (!r.converged) break;
    current = r.model;
  }
  return r;
}

}  // namespace imucal::navfilter
