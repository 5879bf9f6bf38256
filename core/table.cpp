#include "core/table.hpp"

#include <cmath>

#include <Eigen/Geometry>

namespace imucal::table {

using Eigen::Matrix3d;
using Eigen::Vector3d;

namespace {

// The elementary rotations from their angle's cosine and sine.
Matrix3d Rx_cs(double c, double s) {
  Matrix3d r;
  r << 1, 0, 0, 0, c, -s, 0, s, c;
  return r;
}

Matrix3d Rz_cs(double c, double s) {
  Matrix3d r;
  r << c, -s, 0, s, c, 0, 0, 0, 1;
  return r;
}

}  // namespace

Matrix3d Rx(double a_rad) { return Rx_cs(std::cos(a_rad), std::sin(a_rad)); }

Matrix3d Rz(double a_rad) { return Rz_cs(std::cos(a_rad), std::sin(a_rad)); }

// The rotations by minus an angle use cos(-a) = cos(a) and sin(-a) = -sin(a), which the C
// library's sine and cosine keep exactly (they reduce |a| and restore the sign).
struct TableKinematics::AngleTrig {
  explicit AngleTrig(const Vector3d& angle_rad) {
    for (int j = 0; j < 3; ++j) {
      c[j] = std::cos(angle_rad[j]);
      s[j] = std::sin(angle_rad[j]);
    }
  }
  std::array<double, 3> c{}, s{};
  Matrix3d Rz(int axis) const { return Rz_cs(c[axis], s[axis]); }
  Matrix3d Rx(int axis) const { return Rx_cs(c[axis], s[axis]); }
  Matrix3d Rz_minus(int axis) const { return Rz_cs(c[axis], -s[axis]); }
  Matrix3d Rx_minus(int axis) const { return Rx_cs(c[axis], -s[axis]); }
};

Matrix3d skew(const Vector3d& v) {
  Matrix3d m;
  m << 0, -v.z(), v.y(), v.z(), 0, -v.x(), -v.y(), v.x(), 0;
  return m;
}

Matrix3d C_p0_n(double middle_axis_azimuth_rad) {
  const double s = std::sin(middle_axis_azimuth_rad), c = std::cos(middle_axis_azimuth_rad);
  Matrix3d m;
  m.col(0) << s, c, 0;    // xi0: the middle axis
  m.col(1) << -c, s, 0;   // eta0 = zeta0 x xi0
  m.col(2) << 0, 0, 1;    // zeta0: Up
  return m;
}

Matrix3d C_p_n(const Vector3d& angle_rad, const Matrix3d& C_p0_n) {
  // The ideal table: the one product below with the geometry's rotations the identity.
  return TableKinematics::ideal_C_p_n(angle_rad, C_p0_n);
}

PlatformRates platform_rates(const AxisState& axes) {
  static const TableKinematics ideal(0.0);  // the rates do not depend on the azimuth
  return ideal.platform_rates(axes);
}

bool TableGeometry::ideal() const {
  const auto zero = [](const std::array<double, 2>& v) { return v[0] == 0.0 && v[1] == 0.0; };
  if (!zero(outer_tilt_rad) || !zero(middle_axis_rad) || !zero(inner_axis_rad)) return false;
  for (const auto& axis : encoder_error)
    for (const EncoderHarmonic& h : axis)
      if (h.amplitude_rad != 0.0) return false;
  return true;
}

namespace {

// E(v) of CONVENTIONS.md, I + [v x] to first order. Taken as the exact rotation so that C_p_n
// stays orthonormal (the navigation makes a quaternion of it); the two differ by |v|^2 / 2,
// 5e-11 rad for 3", far below anything a table certificate resolves.
Matrix3d small_rotation(const Vector3d& v_rad) {
  const double angle = v_rad.norm();
  if (angle == 0.0) return Matrix3d::Identity();
  return Eigen::AngleAxisd(angle, v_rad / angle).toRotationMatrix();
}

}  // namespace

TableKinematics::TableKinematics(double middle_axis_azimuth_rad, const TableGeometry& geometry)
    : C_p0_n_(table::C_p0_n(middle_axis_azimuth_rad)),
      E_t_(small_rotation(Vector3d(geometry.outer_tilt_rad[0], geometry.outer_tilt_rad[1], 0.0))),
      E_m_(small_rotation(Vector3d(0.0, geometry.middle_axis_rad[0], geometry.middle_axis_rad[1]))),
      E_k_(small_rotation(Vector3d(geometry.inner_axis_rad[0], geometry.inner_axis_rad[1], 0.0))),
      encoder_error_(geometry.encoder_error),
      ideal_(geometry.ideal()) {
  // Terms with no amplitude cost a sine per axis and sample for nothing.
  for (auto& axis : encoder_error_) std::erase_if(axis, [](const EncoderHarmonic& h) { return h.amplitude_rad == 0.0; });
}

Matrix3d TableKinematics::ideal_C_p_n(const Vector3d& angle_rad, const Matrix3d& C_p0_n) {
  return Rz(angle_rad[0]) * C_p0_n * Rx(angle_rad[1]) * Rz(angle_rad[2]);
}

Vector3d TableKinematics::true_angles_rad(const Vector3d& encoder_rad) const {
  Vector3d out = encoder_rad;
  for (int axis = 0; axis < 3; ++axis)
    for (const EncoderHarmonic& h : encoder_error_[static_cast<std::size_t>(axis)])
      out[axis] += h.amplitude_rad * std::sin(h.k * encoder_rad[axis] + h.phase_rad);
  return out;
}

Vector3d TableKinematics::encoder_angles_rad(const Vector3d& true_rad) const {
  Vector3d enc = true_rad;
  // th_enc = th - e(th_enc): each pass shrinks the error by a k (a few 1e-5 for arc seconds), so
  // three passes leave nothing of a 1e-5 rad error at double precision.
  for (int pass = 0; pass < 3; ++pass) enc = true_rad - (true_angles_rad(enc) - enc);
  return enc;
}

AxisState TableKinematics::true_axes(const AxisState& encoder) const {
  AxisState out = encoder;
  for (int axis = 0; axis < 3; ++axis) {
    double slope = 0.0, curvature = 0.0;  // de/dth_enc, d2e/dth_enc2
    for (const EncoderHarmonic& h : encoder_error_[static_cast<std::size_t>(axis)]) {
      const double x = h.k * encoder.angle_rad[axis] + h.phase_rad;
      out.angle_rad[axis] += h.amplitude_rad * std::sin(x);
      slope += h.amplitude_rad * h.k * std::cos(x);
      curvature -= h.amplitude_rad * h.k * h.k * std::sin(x);
    }
    if (slope == 0.0 && curvature == 0.0) continue;
    const double rate = encoder.rate_radps[axis];
    out.rate_radps[axis] = (1.0 + slope) * rate;
    out.accel_radps2[axis] = (1.0 + slope) * encoder.accel_radps2[axis] + curvature * rate * rate;
  }
  return out;
}

Matrix3d TableKinematics::C_p_n(const Vector3d& true_rad) const { return C_p_n(AngleTrig(true_rad)); }

Matrix3d TableKinematics::C_p_n(const AngleTrig& trig) const {
  if (ideal_) return trig.Rz(0) * C_p0_n_ * trig.Rx(1) * trig.Rz(2);
  return E_t_ * trig.Rz(0) * C_p0_n_ * E_m_ * trig.Rx(1) * E_k_ * trig.Rz(2);
}

// The outer gimbal turns about E(t) Up, which is Up in its own frame: the tilt leans the platform
// but leaves the rate resolved in p alone. C_p0_n^T Up = Up. So, in p:
//   outer:  Rz(-th_i) E(k)^T Rx(-th_m) E(m)^T e3
//   middle: Rz(-th_i) E(k)^T e1
//   inner:  e3
Matrix3d TableKinematics::gimbal_axes_p(const Vector3d& true_rad) const {
  const Vector3d e1 = Vector3d::UnitX(), e3 = Vector3d::UnitZ();
  const Matrix3d A = Rz(-true_rad[2]);
  Matrix3d axes;
  if (ideal_) {
    axes.col(0) = A * (Rx(-true_rad[1]) * e3);
    axes.col(1) = A * e1;
  } else {
    axes.col(0) = A * (E_k_.transpose() * (Rx(-true_rad[1]) * (E_m_.transpose() * e3)));
    axes.col(1) = A * (E_k_.transpose() * e1);
  }
  axes.col(2) = e3;
  return axes;
}

PlatformRates TableKinematics::platform_rates(const AxisState& axes) const {
  return platform_rates(axes, AngleTrig(axes.angle_rad));
}

TableKinematics::Pose TableKinematics::pose(const AxisState& true_axes) const {
  const AngleTrig trig(true_axes.angle_rad);
  return {C_p_n(trig), platform_rates(true_axes, trig)};
}

PlatformRates TableKinematics::platform_rates(const AxisState& axes, const AngleTrig& trig) const {
  const Vector3d e1 = Vector3d::UnitX(), e3 = Vector3d::UnitZ();
  const Matrix3d A = trig.Rz_minus(2);
  // B_e3: the outer axis in the middle gimbal's frame after its rotation; k_e1: the middle axis in
  // the inner gimbal's frame; both turn with the gimbals inside them.
  const Vector3d Em_e3 = ideal_ ? e3 : Vector3d(E_m_.transpose() * e3);
  const Vector3d B_e3 = trig.Rx_minus(1) * Em_e3;
  const Matrix3d Ek_T = E_k_.transpose();
  const Vector3d a_o = ideal_ ? Vector3d(A * B_e3) : Vector3d(A * (Ek_T * B_e3));
  const Vector3d a_m = ideal_ ? Vector3d(A * e1) : Vector3d(A * (Ek_T * e1));
  const double d_o = axes.rate_radps[0], d_m = axes.rate_radps[1], d_i = axes.rate_radps[2];
  const double dd_o = axes.accel_radps2[0], dd_m = axes.accel_radps2[1], dd_i = axes.accel_radps2[2];
  PlatformRates out;
  out.w_np_p = a_o * d_o + a_m * d_m + e3 * d_i;
  // d/dt Rz(-th_i) = -d_i [e3 x] Rz(-th_i) and d/dt Rx(-th_m) = -d_m [e1 x] Rx(-th_m), exact for
  // these elementary rotations; the geometry's rotations are constant.
  const Vector3d dB_e3 = -d_m * e1.cross(B_e3);
  const Vector3d A_dB_e3 = ideal_ ? Vector3d(A * dB_e3) : Vector3d(A * (Ek_T * dB_e3));
  const Vector3d da_o = -d_i * e3.cross(a_o) + A_dB_e3;
  const Vector3d da_m = -d_i * e3.cross(a_m);
  out.dw_np_p = da_o * d_o + a_o * dd_o + da_m * d_m + a_m * dd_m + e3 * dd_i;
  return out;
}

}  // namespace imucal::table
