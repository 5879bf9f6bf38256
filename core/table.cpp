#include "core/table.hpp"

#include <cmath>

#include <Eigen/Geometry>

namespace imucal::table {

Eigen::Matrix3d Rx(double a_rad) {
  const double c = std::cos(a_rad), s = std::sin(a_rad);
  Eigen::Matrix3d r;
  r << 1, 0, 0, 0, c, -s, 0, s, c;
  return r;
}

Eigen::Matrix3d Rz(double a_rad) {
  const double c = std::cos(a_rad), s = std::sin(a_rad);
  Eigen::Matrix3d r;
  r << c, -s, 0, s, c, 0, 0, 0, 1;
  return r;
}

Eigen::Matrix3d skew(const Eigen::Vector3d& v) {
  Eigen::Matrix3d m;
  m << 0, -v.z(), v.y(), v.z(), 0, -v.x(), -v.y(), v.x(), 0;
  return m;
}

Eigen::Matrix3d C_p0_n(double middle_axis_azimuth_rad) {
  const double s = std::sin(middle_axis_azimuth_rad), c = std::cos(middle_axis_azimuth_rad);
  Eigen::Matrix3d m;
  m.col(0) << s, c, 0;    // xi0: the middle axis
  m.col(1) << -c, s, 0;   // eta0 = zeta0 x xi0
  m.col(2) << 0, 0, 1;    // zeta0: Up
  return m;
}

Eigen::Matrix3d C_p_n(const Eigen::Vector3d& angle_rad, const Eigen::Matrix3d& C_p0_n) {
  return Rz(angle_rad[0]) * C_p0_n * Rx(angle_rad[1]) * Rz(angle_rad[2]);
}

PlatformRates platform_rates(const AxisState& axes) {
  // w_np_p = A B e3 do + A e1 dm + e3 di with A = Rz(-inner), B = Rx(-middle).
  const Eigen::Vector3d e1 = Eigen::Vector3d::UnitX(), e3 = Eigen::Vector3d::UnitZ();
  const Eigen::Matrix3d A = Rz(-axes.angle_rad[2]);
  const Eigen::Matrix3d B = Rx(-axes.angle_rad[1]);
  const double d_o = axes.rate_radps[0], d_m = axes.rate_radps[1], d_i = axes.rate_radps[2];
  const double dd_o = axes.accel_radps2[0], dd_m = axes.accel_radps2[1], dd_i = axes.accel_radps2[2];
  const Eigen::Vector3d Be3 = B * e3;
  PlatformRates out;
  out.w_np_p = A * Be3 * d_o + A * e1 * d_m + e3 * d_i;
  // dA/dt = -d_i [e3 x] A and dB/dt = -d_m [e1 x] B, both exact for these elementary rotations.
  const Eigen::Vector3d dA_Be3 = -d_i * e3.cross(A * Be3);
  const Eigen::Vector3d A_dBe3 = A * (-d_m * e1.cross(Be3));
  const Eigen::Vector3d dA_e1 = -d_i * e3.cross(A * e1);
  out.dw_np_p = (dA_Be3 + A_dBe3) * d_o + A * Be3 * dd_o + dA_e1 * d_m + A * e1 * dd_m + e3 * dd_i;
  return out;
}

}  // namespace imucal::table
