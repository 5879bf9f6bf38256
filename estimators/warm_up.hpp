// The warm-up test (IEEE Std 952's warm-up, for gyros and accelerometers alike): one static from
// power-on; each channel's output, averaged over bins, is fitted with
//   y(t) = settled + amplitude exp(-(t - t_on) / time_constant)
// (a grid over the time constant, then a golden-section search, the two linear terms solved at
// each), giving the transient's amplitude and time constant with their sigmas and the time from
// power-on until the transient stays inside a band. Pure: frames are pushed in, the result comes
// out.
#pragma once

#include <array>
#include <memory>
#include <string>
#include <vector>

#include "core/imu_model.hpp"
#include "core/recording.hpp"

namespace imucal::warm_up {

struct Options {
  double bin_s = 10.0;           // the output is averaged over bins this long before the fit
  double power_on_s = 0.0;       // program time of the power-on: the run starts as the IMU is switched on
  double gyro_band_dph = 0.01;   // settled: the transient stays within these
  double accel_band_ug = 1.0;
  // A transient is reported when the fit with it lowers the sum of squares by this many times the
  // residual variance (a chi-square of two more parameters: 25 is far beyond chance).
  double detection_chi2 = 25.0;
};

// One channel's transient, in SI units (rad/s for gyros, m/s^2 for accelerometers).
struct Channel {
  bool gyro = true;
  int axis = 0;
  bool detected = false;      // false: no transient above the noise; amplitude and time constant are what the fit found
  bool resolved = true;       // false: the time constant is longer than the run (run longer)
  double amplitude = 0, amplitude_sigma = 0;
  double time_constant_s = 0, time_constant_sigma_s = 0;
  double settle_time_s = 0, settle_time_sigma_s = 0;  // from power-on, 0 when never outside the band
  double band = 0;
  double residual_rms = 0;    // of the bin means about the fit
  double chi2_gain = 0;       // what the transient took out of the sum of squares, in residual variances
};

struct Result {
  // The prior with the turn-on section's warm-up terms (core/turn_on.hpp) replaced by the detected
  // transients (zero elsewhere), each with its sigma; the repeatability terms kept.
  ImuModel model;
  std::array<Channel, 6> channels;  // gyro x y z, accelerometer x y z
  // The bins: time since power-on (s) and each channel's mean less its settled value (SI), for a
  // plot with the fitted transient.
  std::vector<double> t_s;
  std::array<std::vector<double>, 6> deviation;
  double duration_s = 0;  // of the static, from power-on
  std::vector<std::string> notes;
};

class WarmUpEstimator {
 public:
  // meta.segments must list the static (the built-in warm-up programs do); frames of other
  // segments are ignored.
  explicit WarmUpEstimator(const RecordingMeta& meta, Options options = {});
  ~WarmUpEstimator();
  WarmUpEstimator(const WarmUpEstimator&) = delete;
  WarmUpEstimator& operator=(const WarmUpEstimator&) = delete;
  void push(const ImuFrame& frame);
  // Throws std::runtime_error when the statics cannot give a warm-up (too short, or at more than
  // one orientation).
  Result finish(const ImuModel& prior = {}) const;
  int bins_seen() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace imucal::warm_up
