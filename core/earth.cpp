#include "core/earth.hpp"

#include <cmath>
#include <numbers>

namespace imucal::earth {

double normal_gravity_mps2(double latitude_rad, double height_m) {
  // Somigliana's closed form with the WGS-84 equatorial and polar normal gravity.
  constexpr double g_equator = 9.7803253359;
  constexpr double g_pole = 9.8321849378;
  constexpr double k = (kB_m * g_pole) / (kA_m * g_equator) - 1.0;
  const double s2 = std::sin(latitude_rad) * std::sin(latitude_rad);
  const double g0 = g_equator * (1.0 + k * s2) / std::sqrt(1.0 - kE2 * s2);
  const double m = kOmega_radps * kOmega_radps * kA_m * kA_m * kB_m / kGM;
  const double h = height_m;
  return g0 * (1.0 - 2.0 * h / kA_m * (1.0 + kF + m - 2.0 * kF * s2) + 3.0 * h * h / (kA_m * kA_m));
}

double site_gravity_mps2(const Site& site) {
  if (site.gravity_mps2) return *site.gravity_mps2;
  return normal_gravity_mps2(site.latitude_deg * std::numbers::pi / 180.0, site.height_m);
}

double site_gravity_sigma_mps2(const Site& site) {
  return site.gravity_mps2 ? kMeasuredGravitySigma_mps2 : kNormalGravitySigma_mps2;
}

Eigen::Vector3d w_ie_n(double latitude_rad) {
  return {0.0, kOmega_radps * std::cos(latitude_rad), kOmega_radps * std::sin(latitude_rad)};
}

double meridian_radius_m(double latitude_rad) {
  const double s2 = std::sin(latitude_rad) * std::sin(latitude_rad);
  return kA_m * (1.0 - kE2) / std::pow(1.0 - kE2 * s2, 1.5);
}

double prime_vertical_radius_m(double latitude_rad) {
  const double s2 = std::sin(latitude_rad) * std::sin(latitude_rad);
  return kA_m / std::sqrt(1.0 - kE2 * s2);
}

}  // namespace imucal::earth
