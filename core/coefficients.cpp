#include "core/coefficients.hpp"

#include "core/units.hpp"

namespace imucal {

std::vector<Coefficient> model_coefficients(const ImuModel& model) {
  const ImuErrorSet zero{};
  const ImuErrorSet& sigma = model.sigma ? *model.sigma : zero;
  static constexpr const char* kAxes[3] = {"x", "y", "z"};
  std::vector<Coefficient> out;
  auto vec = [&](const std::string& prefix, const Eigen::Vector3d& v, const Eigen::Vector3d& s, double scale,
                 bool optional) {
    for (int j = 0; j < 3; ++j) out.push_back({prefix + "." + kAxes[j], v[j] * scale, s[j] * scale, optional, prefix});
  };
  auto mis = [&](const std::string& prefix, const Misalignment& v, const Misalignment& s) {
    for (const auto& [name, k] : kMisalignmentKeys)
      out.push_back({prefix + "." + name, v.*k * units::kRadToArcsec, s.*k * units::kRadToArcsec, false, prefix});
  };
  // Rows j (the sensor), columns k: "<prefix>.<axis j><sep><column k>".
  auto mat = [&](const std::string& prefix, const Eigen::Matrix3d& v, const Eigen::Matrix3d& s, double scale,
                 const char* const columns[3]) {
    for (int j = 0; j < 3; ++j)
      for (int k = 0; k < 3; ++k) {
        std::string key = prefix + "." + kAxes[j] + "." + columns[k];
        out.push_back({key, v(j, k) * scale, s(j, k) * scale, true, key});
      }
  };
  const GyroErrors& g = model.gyro;
  const AccelErrors& a = model.accel;
  vec("gyro.bias_dph", g.bias_radps, sigma.gyro.bias_radps, units::kRadpsToDph, false);
  vec("gyro.scale_pos_ppm", g.scale_pos, sigma.gyro.scale_pos, 1e6, false);
  vec("gyro.scale_neg_ppm", g.scale_neg, sigma.gyro.scale_neg, 1e6, false);
  mis("gyro.misalignment_arcsec", g.misalignment_rad, sigma.gyro.misalignment_rad);
  vec("accel.bias_mps2", a.bias_mps2, sigma.accel.bias_mps2, 1.0, false);
  vec("accel.scale_ppm", a.scale, sigma.accel.scale, 1e6, false);
  mis("accel.misalignment_arcsec", a.misalignment_rad, sigma.accel.misalignment_rad);
  static constexpr const char* kTerms[3] = {"c1", "c2", "c3"};
  mat("gyro.scale_nonlinear_ppm", g.scale_nonlinear, sigma.gyro.scale_nonlinear, 1e6, kTerms);
  vec("accel.k2_ug_per_g2", a.k2_per_g, sigma.accel.k2_per_g, 1e6, true);
  vec("accel.k3_ug_per_g3", a.k3_per_g2, sigma.accel.k3_per_g2, 1e6, true);
  mat("gyro.g_sensitivity_dph_per_g", g.g_sensitivity_radps_per_g, sigma.gyro.g_sensitivity_radps_per_g,
      units::kRadpsToDph, kAxes);
  vec("gyro.delay_us", g.delay_s, sigma.gyro.delay_s, 1e6, true);
  vec("accel.delay_us", a.delay_s, sigma.accel.delay_s, 1e6, true);
  vec("accel.lever_arm_mm.y", a.lever_arm_y_m, sigma.accel.lever_arm_y_m, 1e3, true);
  vec("accel.lever_arm_mm.z", a.lever_arm_z_m, sigma.accel.lever_arm_z_m, 1e3, true);
  return out;
}

}  // namespace imucal
