#include "estimators/table_reference.hpp"

#include <cmath>

#include <Eigen/Geometry>

#include "core/earth.hpp"
#include "core/table.hpp"
#include "core/units.hpp"

namespace imucal::table_reference {

using Eigen::Matrix3d;
using Eigen::Vector3d;
using units::kDegToRad;

FrameReference::FrameReference(const RecordingMeta& meta)
    : table_(table_kinematics(meta)),
      C_o_p_(meta.mount.C_o_p),
      w_ie_n_(earth::w_ie_n(meta.site.latitude_deg * kDegToRad)),
      g_mps2_(earth::site_gravity_mps2(meta.site)) {}

Vector3d FrameReference::increment_o_rad(const Vector3d& angles0_deg, const Vector3d& angles1_deg, double dt_s,
                                         const Vector3d& accel_radps2) const {
  // The encoders' periodic errors taken out at the ends: the true increment is exact however the
  // table moved in between. The acceleration comes from the encoder's increments: the error's
  // slope (a k, 1e-5) changes it by that fraction of a term that is itself dt^2 small.
  const Vector3d a0 = table_.true_angles_rad(angles0_deg * kDegToRad), a1 = table_.true_angles_rad(angles1_deg * kDegToRad);
  const Vector3d mid = 0.5 * (a0 + a1) - accel_radps2 * (dt_s * dt_s / 12.0), d = a1 - a0;
  const Vector3d wdt_p = table_.gimbal_axes_p(mid) * d;
  const Matrix3d C_p_n = table_.C_p_n(mid);
  // The Earth rate along the path: resolved at the mid attitude, its part across the platform's
  // rotation over the frame averages to sinc(phi/2) of that (exact for a rotation about a fixed
  // axis). The plain midpoint rule left a systematic error of phi^2/24 of it: 0.0016" in a gyro
  // misalignment at 20 Hz and 30 deg/s, beyond 4 sigma of an error-free IMU's fit at any rate.
  Vector3d earth_p = C_p_n.transpose() * w_ie_n_ * dt_s;
  const double phi = wdt_p.norm();
  if (phi > 1e-12) {
    const Vector3d axis = wdt_p / phi;
    const Vector3d along = axis * axis.dot(earth_p);
    earth_p = along + std::sin(0.5 * phi) / (0.5 * phi) * (earth_p - along);
  }
  return C_o_p_.transpose() * (wdt_p + earth_p);
}

Vector3d FrameReference::next_increment_o_rad(const Vector3d& angles0_deg, const Vector3d& angles1_deg, double dt_s) {
  const Vector3d rate_radps = dt_s > 0 ? Vector3d((angles1_deg - angles0_deg) * kDegToRad / dt_s) : Vector3d::Zero();
  Vector3d accel_radps2 = Vector3d::Zero();
  // A backward difference: the acceleration half a frame early, which leaves a third-order error.
  if (have_last_ && angles0_deg == last_end_deg_ && dt_s > 0 && last_dt_s_ > 0)
    accel_radps2 = (rate_radps - last_rate_radps_) / (0.5 * (dt_s + last_dt_s_));
  last_rate_radps_ = rate_radps;
  last_end_deg_ = angles1_deg;
  last_dt_s_ = dt_s;
  have_last_ = true;
  return increment_o_rad(angles0_deg, angles1_deg, dt_s, accel_radps2);
}

Vector3d FrameReference::specific_force_at_rest_o_mps2(const Vector3d& angles_deg) const {
  const Matrix3d C_o_n = table_.C_p_n(table_.true_angles_rad(angles_deg * kDegToRad)) * C_o_p_;
  return C_o_n.transpose() * Vector3d(0, 0, g_mps2_);
}

int SegmentFrames::assign(double t_prev_s, double t_s) {
  constexpr double eps = 1e-7;  // the segment times are rounded program times; frames are on ns
  while (cursor_ < spans_.size() && t_prev_s >= spans_[cursor_].t1_s - eps) ++cursor_;
  for (std::size_t i = cursor_; i < spans_.size() && spans_[i].t0_s < t_s - eps; ++i) {
    const Span& s = spans_[i];
    if (t_prev_s >= s.t1_s - eps) continue;
    if (s.overlapping || (t_prev_s >= s.t0_s - eps && t_s <= s.t1_s + eps)) return static_cast<int>(i);
  }
  return -1;
}

}  // namespace imucal::table_reference

namespace imucal::table_reference {

std::optional<FrameInterval> FrameIntervals::next(const ImuFrame& frame) {
  std::optional<FrameInterval> out;
  if (prev_) {
    const double t_prev = static_cast<double>(prev_->t_ns) * 1e-9, t = static_cast<double>(frame.t_ns) * 1e-9;
    out = FrameInterval{*prev_, t_prev, t, t - t_prev};
  }
  prev_ = frame;
  return out;
}

}  // namespace imucal::table_reference
