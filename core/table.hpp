// Three-axis table kinematics of CONVENTIONS.md: platform attitude C_p_n from the table's angles,
// the platform's rate w_np_p and angular acceleration relative to the local level frame, and the
// table's own errors (CONVENTIONS.md, "The table's own errors"): a leaning outer axis, axes not
// perpendicular, encoders with periodic errors. TableKinematics is the one implementation every
// reference (estimators) and the simulator go through; the free functions C_p_n and
// platform_rates are the ideal table, the same code with the geometry zero.
#pragma once

#include <array>
#include <optional>
#include <string>
#include <vector>

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

// The ideal table: C_p_n = Rz(outer) * C_p0_n * Rx(middle) * Rz(inner).
Eigen::Matrix3d C_p_n(const Eigen::Vector3d& angle_rad, const Eigen::Matrix3d& C_p0_n);

// Platform kinematics relative to n, resolved in p: rate and its time derivative.
struct PlatformRates {
  Eigen::Vector3d w_np_p;
  Eigen::Vector3d dw_np_p;  // d/dt of w_np_p (components in p)
};
// The ideal table's (true angles, rates and accelerations).
PlatformRates platform_rates(const AxisState& axes);

// One periodic term of an encoder's error: the true angle is th_enc + amplitude sin(k th_enc + phase).
struct EncoderHarmonic {
  int k = 1;
  double amplitude_rad = 0.0;
  double phase_rad = 0.0;
  bool operator==(const EncoderHarmonic&) const = default;
};

// The table's own errors (all zero: the ideal table). As a certificate's 1-sigma (TableCertificate::
// sigma) the same fields hold the standard uncertainty of each value.
struct TableGeometry {
  // [e, n]: the outer axis is E([e, n, 0]) Up, a rotation about East and about North.
  std::array<double, 2> outer_tilt_rad{0.0, 0.0};
  // [y, z]: m = [0, y, z] in the outer gimbal's frame: y the outer/middle non-perpendicularity,
  // z the middle axis's azimuth offset.
  std::array<double, 2> middle_axis_rad{0.0, 0.0};
  // [x, y]: k = [x, y, 0] after the middle rotation: x the middle encoder's zero offset, y the
  // middle/inner non-perpendicularity.
  std::array<double, 2> inner_axis_rad{0.0, 0.0};
  std::array<std::vector<EncoderHarmonic>, 3> encoder_error;  // outer, middle, inner

  bool ideal() const;
  bool operator==(const TableGeometry&) const = default;
};

// meta.json's `table` (formats.md): the values a certificate gives, their 1-sigma, and its name.
// No geometry: the values are unknown and the ideal table is the reference.
struct TableCertificate {
  std::optional<TableGeometry> geometry;
  std::optional<TableGeometry> sigma;
  std::string certificate;
  bool operator==(const TableCertificate&) const = default;
};

// The table a recording was made on: its site's middle-axis azimuth and its own errors.
class TableKinematics {
 public:
  explicit TableKinematics(double middle_axis_azimuth_rad, const TableGeometry& geometry = {});

  // True angles from encoder angles: th = th_enc + sum a sin(k th_enc + phi), per axis.
  Eigen::Vector3d true_angles_rad(const Eigen::Vector3d& encoder_rad) const;
  // The inverse (what the encoders read when the table stands at true_rad), by fixed-point
  // iteration; exact to rounding for any certified table (contraction a k < 1e-4).
  Eigen::Vector3d encoder_angles_rad(const Eigen::Vector3d& true_rad) const;
  // True angles, rates and accelerations from the encoder's: the rate scaled by the error's
  // slope, the acceleration by it and by its curvature times the rate squared.
  AxisState true_axes(const AxisState& encoder) const;

  // C_p_n = E(t) Rz(th_o) C_p0_n E(m) Rx(th_m) E(k) Rz(th_i), true angles.
  Eigen::Matrix3d C_p_n(const Eigen::Vector3d& true_rad) const;
  // The three gimbal axes resolved in p at these true angles, as columns: w_np_p is this matrix
  // times the true gimbal rates (each gimbal turns about its own, erroneous, axis).
  Eigen::Matrix3d gimbal_axes_p(const Eigen::Vector3d& true_rad) const;
  // Rate and its derivative from true angles, rates and accelerations.
  PlatformRates platform_rates(const AxisState& true_axes) const;
  // Both of the above at once: the simulator needs them at every quadrature node, and the
  // angles' sines and cosines, the most of their cost, are then taken once. The same numbers,
  // bit for bit, as C_p_n and platform_rates called apart.
  struct Pose {
    Eigen::Matrix3d C_p_n;
    PlatformRates rates;
  };
  Pose pose(const AxisState& true_axes) const;

  const Eigen::Matrix3d& C_p0_n() const { return C_p0_n_; }
  bool ideal() const { return ideal_; }
  // The ideal table's product (the free C_p_n).
  static Eigen::Matrix3d ideal_C_p_n(const Eigen::Vector3d& angle_rad, const Eigen::Matrix3d& C_p0_n);

 private:
  struct AngleTrig;  // the three angles' cosines and sines
  Eigen::Matrix3d C_p_n(const AngleTrig& trig) const;
  PlatformRates platform_rates(const AxisState& true_axes, const AngleTrig& trig) const;

  Eigen::Matrix3d C_p0_n_;
  Eigen::Matrix3d E_t_, E_m_, E_k_;  // the small rotations of the geometry (identity when ideal)
  std::array<std::vector<EncoderHarmonic>, 3> encoder_error_;
  bool ideal_ = true;
};

}  // namespace imucal::table
