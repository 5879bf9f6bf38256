// The moments of a rate increment that the gyro scale nonlinearity acts through (CONVENTIONS.md,
// "Nonlinear terms"): for a frame turning o by wdt_o (rad, the table's reference) over dt_s, row
// k holds q_k dtheta_k, q_k^2 dtheta_k and q_k^3 dtheta_k with q_k = |w_k| / 100 deg/s; the
// nonlinear part of gyro k's angle is row k of scale_nonlinear times row k of these. One rule for
// stage 1 (which removes a known nonlinearity) and the rate-steps test (which fits it).
#pragma once

#include <cmath>

#include <Eigen/Core>

#include "core/imu_model.hpp"

namespace imucal::rate_moments {

inline Eigen::Matrix3d of(const Eigen::Vector3d& wdt_o_rad, double dt_s) {
  Eigen::Matrix3d m = Eigen::Matrix3d::Zero();
  if (!(dt_s > 0)) return m;
  for (int k = 0; k < 3; ++k) {
    const double q = std::abs(wdt_o_rad[k]) / dt_s / kGyroNonlinearityRate_radps;
    m.row(k) = Eigen::RowVector3d(q, q * q, q * q * q) * wdt_o_rad[k];
  }
  return m;
}

}  // namespace imucal::rate_moments
