// A unit's turn-on terms: what its biases do from one power-on to the next and in the first
// minutes after each (IEEE Std 952's turn-on to turn-on repeatability and warm-up). imucal's own
// section of imucal-imu-model/1, optional, "turn_on" (docs/calibration.md, "Turn-on terms"):
//
//   "turn_on": {"gyro":  {"bias_repeatability_dph": [x, y, z], "warm_up_dph": [x, y, z],
//                         "warm_up_time_constant_s": [x, y, z]},
//               "accel": {"bias_repeatability_mps2": [...], "warm_up_mps2": [...],
//                         "warm_up_time_constant_s": [...]},
//               "sigma": {"gyro": {...same keys...}, "accel": {...}}}
//
// After a power-on at t_on, channel j's bias is its constant plus an offset that power-on drew
// (1-sigma bias_repeatability[j]) plus warm_up[j] exp(-(t - t_on) / warm_up_time_constant[j]).
// A truth file gives the simulator these; the warm-up stage writes the transient it measured.
#pragma once

#include <optional>
#include <string>

#include <Eigen/Core>
#include <nlohmann/json_fwd.hpp>

#include "core/imu_model.hpp"

namespace imucal {

struct TurnOnTerms {
  Eigen::Vector3d gyro_repeatability_radps = Eigen::Vector3d::Zero();
  Eigen::Vector3d gyro_warm_up_radps = Eigen::Vector3d::Zero();
  Eigen::Vector3d gyro_time_constant_s = Eigen::Vector3d::Zero();
  Eigen::Vector3d accel_repeatability_mps2 = Eigen::Vector3d::Zero();
  Eigen::Vector3d accel_warm_up_mps2 = Eigen::Vector3d::Zero();
  Eigen::Vector3d accel_time_constant_s = Eigen::Vector3d::Zero();

  // The warm-up transient `since_on_s` after a power-on (zero before it).
  Eigen::Vector3d gyro_transient_radps(double since_on_s) const;
  Eigen::Vector3d accel_transient_mps2(double since_on_s) const;
};

struct TurnOnSection {
  TurnOnTerms value;
  std::optional<TurnOnTerms> sigma;
};

// Parses and checks a "turn_on" section (`where` names it in errors: unknown keys, a transient
// without a positive time constant, a negative repeatability).
TurnOnSection turn_on_from_json(const nlohmann::json& j, const std::string& where);
// The model's section, or nothing when it has none.
std::optional<TurnOnSection> turn_on_of(const ImuModel& model);
// Writes the section into the model (replacing one it had).
void set_turn_on(ImuModel& model, const TurnOnSection& section);

}  // namespace imucal
