// Three-axis table kinematics of CONVENTIONS.md: platform attitude C_p_n from the encoder angles,
// the platform's rate w_np_p and angular acceleration relative to the local level frame.
#pragma once

#include <Eigen/Core>

namespace imucal::table {

// Angles, rates and accelerations of the three gimbals, ordered outer, middle, inner.
struct AxisState {
  Eigen::Vector3d angle_rad = Eigen::Vector3d::Zero();
  Eigen::Vector3d rate_radps = Eigen::Vector3d::Zero();
  Eigen::Vector3d accel_radps2 = Eigen::Vector3d::Zero();
};

Eigen::Matrix3d Rx(double a_rad);
Eigen::Matrix3d Rz(double a_rad);
Eigen::Matrix3d skew(const Eigen::Vector3d& v);

// Platform at all-zero angles: columns xi0, eta0, zeta0 in ENU for the middle-axis azimuth A
// (clockwise from North).
Eigen::Matrix3d C_p0_n(double middle_axis_azimuth_rad);

// C_p_n = Rz(outer) * C_p0_n * Rx(middle) * Rz(inner).
Eigen::Matrix3d C_p_n(const Eigen::Vector3d& angle_rad, const Eigen::Matrix3d& C_p0_n);

// Platform kinematics relative to n, resolved in p: rate and its time derivative.
struct PlatformRates {
  Eigen::Vector3d w_np_p;
  Eigen::Vector3d dw_np_p;  // d/dt of w_np_p (components in p)
};
PlatformRates platform_rates(const AxisState& axes);

}  // namespace imucal::table
