// Turn-on to turn-on bias repeatability (IEEE Std 952): statics after several power-ons of the
// IMU at one orientation (the repeatability programs; a power-on is the run's start and each
// power-cycle segment). Per channel the mean output of each power-on's static; the repeatability
// is the spread of those means (their sample standard deviation) less what the noise within each
// static puts into it. Pure: frames are pushed in, the result comes out.
#pragma once

#include <array>
#include <memory>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "core/imu_model.hpp"
#include "core/recording.hpp"

namespace imucal::repeatability {

using Vector6d = Eigen::Matrix<double, 6, 1>;  // gyro x y z (rad/s), accelerometer x y z (m/s^2)

// One power-on: the statics after it (merged), their mean output and that mean's noise.
struct TurnOn {
  int index = 0;               // 1 for the power-on at the run's start
  std::string segment;         // its first static
  double t0_s = 0, duration_s = 0;
  Vector6d mean = Vector6d::Zero();
  Vector6d mean_sigma = Vector6d::Zero();  // from the scatter of ten blocks of the statics
};

// One channel, SI units.
struct Channel {
  bool gyro = true;
  int axis = 0;
  double repeatability = 0;  // 1-sigma of the bias from one power-on to the next
  // A standard deviation from a few power-ons is uncertain and skewed: its confidence intervals
  // from the chi-square distribution of N - 1 degrees of freedom, at 68.3 % (1 sigma) and 99.73 %
  // (3 sigma); repeatability_sigma is half the 68.3 % interval's width.
  double lo68 = 0, hi68 = 0, lo997 = 0, hi997 = 0;
  double repeatability_sigma = 0;
  double spread = 0;   // the sample standard deviation of the means
  double noise = 0;    // what the noise within the statics puts into it (RMS of the means' sigmas)
};

struct Result {
  // The prior with the turn-on section's bias repeatability (core/turn_on.hpp) replaced, with its
  // sigma; its warm-up terms kept.
  ImuModel model;
  std::vector<TurnOn> turn_ons;
  std::array<Channel, 6> channels;
  std::vector<std::string> notes;
};

class RepeatabilityEstimator {
 public:
  explicit RepeatabilityEstimator(const RecordingMeta& meta);
  ~RepeatabilityEstimator();
  RepeatabilityEstimator(const RepeatabilityEstimator&) = delete;
  RepeatabilityEstimator& operator=(const RepeatabilityEstimator&) = delete;
  void push(const ImuFrame& frame);
  // Throws std::runtime_error naming what is missing: fewer than three power-ons with a static,
  // statics at more than one orientation.
  Result finish(const ImuModel& prior = {}) const;
  int turn_ons_seen() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace imucal::repeatability
