// The table's reference rotation of the instrument frame over one frame interval: the one rule
// every estimator that compares gyro increments with the table's angles uses (stage 1's rest-to-rest
// rotations, the rate-steps test).
#pragma once

#include <Eigen/Core>

#include "core/recording.hpp"

namespace imucal::table_reference {

class FrameReference {
 public:
  explicit FrameReference(const RecordingMeta& meta);
  // Rotation of o relative to inertial space between two frames (table angles in degrees at their
  // ends, dt_s apart), resolved in o, radians: the platform rate from the encoder increments at the
  // mid angles (exact for single-axis motion), plus the Earth rate along the path.
  Eigen::Vector3d increment_o_rad(const Eigen::Vector3d& angles0_deg, const Eigen::Vector3d& angles1_deg,
                                  double dt_s) const;
  // The specific force at rest at these table angles (the gravity reaction), resolved in o.
  Eigen::Vector3d specific_force_at_rest_o_mps2(const Eigen::Vector3d& angles_deg) const;

 private:
  Eigen::Matrix3d C_p0_n_, C_o_p_;
  Eigen::Vector3d w_ie_n_;
  double g_mps2_;
};

}  // namespace imucal::table_reference
