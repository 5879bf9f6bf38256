// Sensor noise from static data (seed: noise levels from the spectra on a still base): overlapping
// Allan deviation and Welch PSD per channel, angle/velocity random walk, bias instability (the
// Allan floor / 0.664, IEEE Std 952). Frames inside static segments are binned (bin_s) as they
// arrive, so a 12 h recording costs a few megabytes; no clock, no I/O.
#pragma once

#include <array>
#include <string>
#include <vector>

#include "core/imu_model.hpp"
#include "core/recording.hpp"

namespace imucal::noise {

struct Options {
  double bin_s = 0.01;             // averaging bin of the stored rate series
  double min_static_s = 10.0;      // shorter statics are ignored
  double min_bias_instability_static_s = 1800.0;  // the floor needs a long record
};

struct ChannelNoise {
  std::vector<double> tau_s, adev;          // rad/s (gyro) or m/s^2 (accel)
  std::vector<double> psd_freq_hz, psd;     // one-sided PSD, (rad/s)^2/Hz or (m/s^2)^2/Hz
  double white = 0;                         // rad/sqrt(s) or (m/s)/sqrt(s)
  double bias_instability = 0;              // rad/s or m/s^2; 0 when the record is too short
};

struct Result {
  std::array<ChannelNoise, 6> channel;      // gyro x y z, accel x y z
  double longest_static_s = 0;
  double total_static_s = 0;
  std::vector<std::string> notes;
  // The model with noise.arw_deg_rth, vrw_mps_rth and (when determined) bias_instability_* set.
  ImuModel apply(const ImuModel& model) const;
  std::string curves_json() const;  // the curve data for plots, stored with the run
};

// Overlapping Allan deviation of a rate series sampled every dt_s, at cluster sizes m.
std::vector<double> overlapping_adev(const std::vector<double>& rate, double dt_s, const std::vector<long>& m);

class NoiseAnalyzer {
 public:
  NoiseAnalyzer(const RecordingMeta& meta, const Options& options = {});
  void push(const ImuFrame& frame);
  Result finish() const;

 private:
  void close_bin();
  RecordingMeta meta_;
  Options options_;
  std::vector<SegmentInfo> statics_;
  std::size_t next_ = 0;
  // Binned rates of each contiguous static run.
  struct Run {
    std::array<std::vector<double>, 6> rate;
  };
  std::vector<Run> runs_;
  bool in_run_ = false;
  std::string run_segment_;
  std::array<double, 6> bin_sum_{};
  double bin_T_ = 0;
  long long prev_t_ns_ = 0;
  bool have_prev_ = false;
};

}  // namespace imucal::noise
