// WGS-84 Earth: rotation rate, normal gravity with the free-air correction, radii of curvature.
// The simulator and the navigation call the same functions (CONVENTIONS.md, "Earth and site").
#pragma once

#include <Eigen/Core>

#include "core/recording.hpp"

namespace imucal::earth {

inline constexpr double kA_m = 6378137.0;
inline constexpr double kF = 1.0 / 298.257223563;
inline constexpr double kB_m = kA_m * (1.0 - kF);
inline constexpr double kE2 = kF * (2.0 - kF);
inline constexpr double kOmega_radps = 7.292115e-5;
inline constexpr double kGM = 3.986004418e14;

// Somigliana normal gravity at geodetic latitude with the free-air correction for height.
double normal_gravity_mps2(double latitude_rad, double height_m);

// The site's g: measured value when the site gives one, otherwise normal gravity.
double site_gravity_mps2(const Site& site);

// The standard uncertainty of site_gravity_mps2 (a type B source of the uncertainty budget, issue
// 34) when nobody states one. A measured g comes from a gravimeter survey tied to the national
// network and carried to the table's axis intersection with the free-air gradient (3.1e-6 m/s^2
// per metre): about 0.1 mGal, 1e-6 m/s^2, 0.1 ppm of an accelerometer's scale factor. Normal
// gravity misses the local g by the site's gravity anomaly, typically tens of mGal: 30 mGal,
// 3e-4 m/s^2, 30 ppm of scale factor, which is why a lab measures its g.
inline constexpr double kMeasuredGravitySigma_mps2 = 1e-6;
inline constexpr double kNormalGravitySigma_mps2 = 3e-4;
double site_gravity_sigma_mps2(const Site& site);

// Earth rate resolved in ENU at latitude.
Eigen::Vector3d w_ie_n(double latitude_rad);

// Meridian (north-south) and prime-vertical (east-west) radii of curvature.
double meridian_radius_m(double latitude_rad);
double prime_vertical_radius_m(double latitude_rad);

}  // namespace imucal::earth
