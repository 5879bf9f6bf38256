// Strapdown inertial navigation in the local-level ENU frame: attitude with coning compensation,
// velocity with rotation and sculling compensation, Earth rate, transport rate and the gravity of
// CONVENTIONS.md (the simulator's own function). The vertical channel is held to a reference, as it
// diverges in any free-inertial solution. Pure: increments in, state out; no clock, no I/O.
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>

namespace imucal::nav {

struct NavState {
  Eigen::Quaterniond q_b_n = Eigen::Quaterniond::Identity();  // body to ENU
  Eigen::Vector3d v_n = Eigen::Vector3d::Zero();               // ENU velocity relative to Earth
  double lat_rad = 0, lon_rad = 0, h_m = 0;
};

class Strapdown {
 public:
  // hold_vertical: after each update the vertical velocity and height are set to the reference
  // (free-inertial judging); false integrates them too (a filter that measures them keeps them).
  Strapdown(const NavState& initial, double gravity_mps2, bool hold_vertical = true);

  // One IMU interval of length dt_s with compensated increments in the body frame.
  void update(const Eigen::Vector3d& dtheta_b, const Eigen::Vector3d& dv_b, double dt_s, double v_up_ref_mps,
              double h_ref_m);

  const NavState& state() const { return s_; }
  NavState& mutable_state() { return s_; }  // for feedback of estimated errors

 private:
  NavState s_;
  double g_mps2_;
  bool hold_vertical_;
  Eigen::Vector3d prev_dtheta_b_ = Eigen::Vector3d::Zero();
  Eigen::Vector3d prev_dv_b_ = Eigen::Vector3d::Zero();
  bool first_ = true;
  int steps_since_normalize_ = 0;
};

// Rotation vector to unit quaternion (exact, with a series near zero).
Eigen::Quaterniond quat_from_rotvec(const Eigen::Vector3d& phi);

}  // namespace imucal::nav
