#include "estimators/strapdown.hpp"

#include <cmath>

#include "core/earth.hpp"

namespace imucal::nav {

using Eigen::Vector3d;

Eigen::Quaterniond quat_from_rotvec(const Vector3d& phi) {
  const double a2 = phi.squaredNorm();
  double c, s_over_a;
  if (a2 < 1e-8) {
    // Taylor series of cos(a/2) and sin(a/2)/a: exact to double precision for |a| < 1e-4.
    c = 1.0 - a2 / 8.0 + a2 * a2 / 384.0;
    s_over_a = 0.5 - a2 / 48.0 + a2 * a2 / 3840.0;
  } else {
    const double a = std::sqrt(a2);
    c = std::cos(0.5 * a);
    s_over_a = std::sin(0.5 * a) / a;
  }
  return {c, s_over_a * phi.x(), s_over_a * phi.y(), s_over_a * phi.z()};
}

Strapdown::Strapdown(const NavState& initial, double gravity_mps2, bool hold_vertical)
    : s_(initial), g_mps2_(gravity_mps2), hold_vertical_(hold_vertical) {}

void Strapdown::update(const Vector3d& dtheta, const Vector3d& dv, double dt, double v_up_ref, double h_ref) {
  if (first_) {
    // No earlier interval: assume the same increments before, which zeroes the two-sample terms.
    prev_dtheta_b_ = dtheta;
    prev_dv_b_ = dv;
    first_ = false;
  }
  const double lat = s_.lat_rad, h = s_.h_m;
  const double RM = earth::meridian_radius_m(lat) + h, RN = earth::prime_vertical_radius_m(lat) + h;
  const Vector3d w_ie = earth::w_ie_n(lat);
  const Vector3d& v = s_.v_n;
  const Vector3d w_en(-v.y() / RM, v.x() / RN, v.x() * std::tan(lat) / RN);
  const Vector3d zeta = (w_ie + w_en) * dt;

  // Velocity: rotation compensation to second order in the rotation (the (1/6) term matters at
  // low rates: without it a steady rotation leaves (w h)^2 / 12 of f, a scale-factor-like error),
  // plus the two-sample sculling term; resolved at the start of the interval and carried half-way
  // through the rotation of the navigation frame.
  const Vector3d dv_rot = 0.5 * dtheta.cross(dv) + dtheta.cross(dtheta.cross(dv)) / 6.0;
  const Vector3d dv_scul = (prev_dtheta_b_.cross(dv) + prev_dv_b_.cross(dtheta)) / 12.0;
  const Vector3d dv_sf_n0 = s_.q_b_n * (dv + dv_rot + dv_scul);
  const Vector3d dv_sf_n = dv_sf_n0 - 0.5 * zeta.cross(dv_sf_n0);
  const Vector3d g_n(0.0, 0.0, -g_mps2_);
  Vector3d v_new = v + dv_sf_n + (g_n - (2.0 * w_ie + w_en).cross(v)) * dt;
  if (hold_vertical_) v_new.z() = v_up_ref;

  // Position: trapezoidal in the horizontal, height held.
  const Vector3d v_mid = 0.5 * (v + v_new);
  s_.lat_rad += v_mid.y() / RM * dt;
  s_.lon_rad += v_mid.x() / (RN * std::cos(lat)) * dt;
  s_.h_m = hold_vertical_ ? h_ref : h + v_mid.z() * dt;
  s_.v_n = v_new;

  // Attitude: body rotation with the two-sample coning correction, navigation-frame rotation.
  const Vector3d phi = dtheta + prev_dtheta_b_.cross(dtheta) / 12.0;
  s_.q_b_n = quat_from_rotvec(-zeta) * s_.q_b_n * quat_from_rotvec(phi);
  if (++steps_since_normalize_ >= 16) {
    s_.q_b_n.normalize();
    steps_since_normalize_ = 0;
  }
  prev_dtheta_b_ = dtheta;
  prev_dv_b_ = dv;
}

}  // namespace imucal::nav
