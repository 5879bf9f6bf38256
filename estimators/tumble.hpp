// The multipoint tumble (IEEE Std 1293 for accelerometers): statics at many angles of a whole turn
// in a vertical plane, in two planes. Per accelerometer a least squares in its own specific force
// and the two across it gives the bias, the scale factor, K2, K3 and the two misalignment angles of
// its row (the harmonics of the tumble angle, without forming them); per gyro, the same statics
// against the specific force give the bias and the g-sensitivity row (CONVENTIONS.md, "Nonlinear
// terms"). Pure: frames are pushed in, the result comes out.
#pragma once

#include <array>
#include <memory>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "core/imu_model.hpp"
#include "core/recording.hpp"

namespace imucal::tumble {

// One static of the tumble.
struct Position {
  std::string segment;
  double duration_s = 0;
  Eigen::Vector3d f_o_mps2 = Eigen::Vector3d::Zero();        // the reference specific force
  Eigen::Vector3d accel_mps2 = Eigen::Vector3d::Zero();      // the accelerometers' mean output
  Eigen::Vector3d accel_residual_mps2 = Eigen::Vector3d::Zero();  // output less the fitted model
  Eigen::Vector3d gyro_residual_radps = Eigen::Vector3d::Zero();
};

struct Result {
  // The prior with the accelerometers' bias, scale, misalignment, K2 and K3 and the gyros' bias
  // and g-sensitivity replaced, each with its sigma.
  ImuModel model;
  std::vector<Position> positions;
  Eigen::Vector3d accel_residual_rms_mps2 = Eigen::Vector3d::Zero();
  Eigen::Vector3d gyro_residual_rms_radps = Eigen::Vector3d::Zero();
  std::vector<std::string> notes;
};

class TumbleEstimator {
 public:
  // meta.segments must list the statics (the built-in tumble programs do).
  explicit TumbleEstimator(const RecordingMeta& meta);
  ~TumbleEstimator();
  TumbleEstimator(const TumbleEstimator&) = delete;
  TumbleEstimator& operator=(const TumbleEstimator&) = delete;
  void push(const ImuFrame& frame);
  // prior: the gyros' scale factors and misalignments that remove the Earth rate from the gyro
  // statics (a stage-1 model; ideal when none is given). Throws std::runtime_error naming what
  // the statics cannot determine.
  Result finish(const ImuModel& prior = {}) const;
  int statics_seen() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace imucal::tumble
