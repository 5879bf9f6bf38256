// The table's reference over one frame interval: the rotation of the instrument frame and the
// specific force at rest, the one rule every estimator that compares the IMU's increments with the
// table's angles uses (stage 1, the rate-steps test, the tumble); and which segment a frame
// belongs to.
#pragma once

#include <optional>
#include <utility>
#include <vector>

#include <Eigen/Core>

#include "core/recording.hpp"
#include "core/table.hpp"

namespace imucal::table_reference {

class FrameReference {
 public:
  explicit FrameReference(const RecordingMeta& meta);
  // Rotation of o relative to inertial space between two frames (the encoders' table angles in
  // degrees at their ends, dt_s apart), resolved in o, radians: the true angles at the ends (the
  // recording's table geometry, core/table), the platform rotation from their increments about
  // the gimbal axes at the mid angles (exact for single-axis motion, about its erroneous axis), plus the Earth rate along the path, resolved at the
  // frame's mean angle. Under an angular acceleration (rad/s^2 per table axis) that is the mid angle
  // less accel dt^2 / 12: the table passes its mid angle late (by accel dt^2 / 8) and the mean of
  // the Earth vector turning with it lies accel dt^2 / 24 back from the time's middle.
  Eigen::Vector3d increment_o_rad(const Eigen::Vector3d& angles0_deg, const Eigen::Vector3d& angles1_deg, double dt_s,
                                  const Eigen::Vector3d& accel_radps2 = Eigen::Vector3d::Zero()) const;
  // The same for the consecutive frames of a recording, call after call, the acceleration from
  // this frame's increment and the last one's (none after a break in the angles). Resolving the
  // Earth rate at the mid angle instead left 3.8e-8 rad on a 180 deg move at 20 Hz, 0.001" in an
  // error-free IMU's gyro angles: beyond the sigma of the fit, which such an IMU gets from exactly
  // that residual.
  Eigen::Vector3d next_increment_o_rad(const Eigen::Vector3d& angles0_deg, const Eigen::Vector3d& angles1_deg,
                                       double dt_s);
  // The specific force at rest at these table angles (the gravity reaction), resolved in o.
  Eigen::Vector3d specific_force_at_rest_o_mps2(const Eigen::Vector3d& angles_deg) const;

 private:
  table::TableKinematics table_;
  Eigen::Matrix3d C_o_p_;
  Eigen::Vector3d w_ie_n_;
  double g_mps2_;
  // next_increment_o_rad: the last frame's mean rates and end angles.
  Eigen::Vector3d last_rate_radps_ = Eigen::Vector3d::Zero(), last_end_deg_ = Eigen::Vector3d::Zero();
  double last_dt_s_ = 0.0;
  bool have_last_ = false;
};

}  // namespace imucal::table_reference

namespace imucal::table_reference {

// Which segment a frame belongs to, the one rule of the estimators that accumulate segments: a
// static takes the frames wholly inside it (the table at rest over each); a motion segment that
// starts and ends at rest takes every frame that overlaps it (its first and last frames straddle
// the rests around it, where nothing moves), so that its integral is rest to rest.
class SegmentFrames {
 public:
  struct Span {
    double t0_s = 0, t1_s = 0;
    bool overlapping = false;  // a rest-to-rest motion; false: a static
  };
  // Spans sorted by t0_s and not overlapping each other.
  explicit SegmentFrames(std::vector<Span> spans) : spans_(std::move(spans)) {}
  // The index of the span the frame interval (t_prev_s, t_s] belongs to, or -1. Frames come in
  // time order.
  int assign(double t_prev_s, double t_s);

 private:
  std::vector<Span> spans_;
  std::size_t cursor_ = 0;
};

}  // namespace imucal::table_reference

namespace imucal::table_reference {

// Consecutive frames as the intervals they close: a frame's increments cover (t_prev, t], where
// t_prev is the frame before's time stamp; the first frame only opens the first interval.
struct FrameInterval {
  ImuFrame prev;
  double t_prev_s = 0, t_s = 0, dt_s = 0;
};
class FrameIntervals {
 public:
  // The interval `frame` closes; nothing for the first frame.
  std::optional<FrameInterval> next(const ImuFrame& frame);

 private:
  std::optional<ImuFrame> prev_;
};

}  // namespace imucal::table_reference
