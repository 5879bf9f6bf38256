// Unit conversions. Code keeps SI internally (rad, rad/s, m/s^2, s); these constants convert at
// the edges (JSON, CLI, reports), where names carry the non-SI unit.
#pragma once

#include <numbers>

namespace imucal::units {

inline constexpr double kPi = std::numbers::pi;
inline constexpr double kDegToRad = kPi / 180.0;
inline constexpr double kRadToDeg = 180.0 / kPi;
inline constexpr double kArcsecToRad = kDegToRad / 3600.0;
inline constexpr double kRadToArcsec = 1.0 / kArcsecToRad;
inline constexpr double kDphToRadps = kDegToRad / 3600.0;  // deg/h -> rad/s
inline constexpr double kRadpsToDph = 1.0 / kDphToRadps;
inline constexpr double kPpm = 1e-6;
inline constexpr double kUsToS = 1e-6;
inline constexpr double kMmToM = 1e-3;
// angle random walk deg/sqrt(h) -> rad/sqrt(s); velocity random walk (m/s)/sqrt(h) -> (m/s)/sqrt(s)
inline constexpr double kDegRthToRadRts = kDegToRad / 60.0;
inline constexpr double kMpsRthToMpsRts = 1.0 / 60.0;
inline constexpr double kNsPerS = 1e9;
// Standard gravity, the "g" of data sheets and of IEEE Std 1293 (CONVENTIONS.md g_std): the unit of
// the accelerometer nonlinearity and of gyro g-sensitivity, whatever the site's gravity.
inline constexpr double kStandardGravity_mps2 = 9.80665;

}  // namespace imucal::units
