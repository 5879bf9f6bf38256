#include "core/coefficients.hpp"

#include <stdexcept>

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

const std::vector<CoefficientQuantity>& coefficient_quantities() {
  using S = KeyShape;
  // The browser's tables show these titles and units as they are (GET /api/schema).
  static const std::vector<CoefficientQuantity> table = {
      {"gyro.bias_dph", "Gyro bias", "°/h", S::axis},
      {"gyro.scale_pos_ppm", "Gyro scale factor (+ rates)", "ppm", S::axis},
      {"gyro.scale_neg_ppm", "Gyro scale factor (− rates)", "ppm", S::axis},
      {"gyro.misalignment_arcsec", "Gyro misalignment", "″", S::angle},
      {"gyro.scale_nonlinear_ppm", "Gyro scale nonlinearity", "ppm", S::terms},
      {"gyro.g_sensitivity_dph_per_g", "Gyro g-sensitivity", "°/h/g", S::coupling},
      {"accel.bias_mps2", "Accelerometer bias", "m/s²", S::axis},
      {"accel.scale_ppm", "Accelerometer scale factor", "ppm", S::axis},
      {"accel.misalignment_arcsec", "Accelerometer misalignment", "″", S::angle},
      {"accel.k2_ug_per_g2", "Accelerometer K2", "µg/g²", S::axis},
      {"accel.k3_ug_per_g3", "Accelerometer K3", "µg/g³", S::axis},
      // The lever-arm stage and stage 3 estimate these too.
      {"gyro.delay_us", "Gyro delay", "µs", S::axis},
      {"accel.delay_us", "Accelerometer delay", "µs", S::axis},
      {"accel.lever_arm_mm", "Proof-mass offsets", "mm", S::proof_mass},
  };
  return table;
}

const CoefficientQuantity& quantity_of(const std::string& key) {
  for (const CoefficientQuantity& q : coefficient_quantities()) {
    const std::string prefix = std::string(q.key) + ".";
    if (key.starts_with(prefix)) return q;
  }
  throw std::logic_error("no quantity of core/coefficients.cpp covers the coefficient '" + key + "'");
}

std::string coefficient_title(const std::string& key) {
  const CoefficientQuantity& q = quantity_of(key);
  const std::string rest = key.substr(std::string(q.key).size() + 1);  // "x", "xy", "y.x", "x.c2"
  const std::string title = q.title;
  const bool pair = rest.size() == 3 && rest[1] == '.';
  switch (q.shape) {
    case KeyShape::axis: return title + ", " + rest + " axis";
    case KeyShape::angle:
      if (rest.size() == 2) return title + ", sensor " + rest[0] + " about " + rest[1];
      break;
    case KeyShape::proof_mass:
      if (pair) return std::string("Proof-mass offset of accelerometer ") + rest[0] + ", " + rest[2] + " component";
      break;
    case KeyShape::coupling:
      if (pair) return title + " of gyro " + rest[0] + " to specific force along " + rest[2];
      break;
    case KeyShape::terms:
      // q = |omega| / 100 deg/s: the gyro's scale nonlinearity (formats.md).
      if (rest.size() == 4 && rest[2] == 'c')
        return title + ", " + rest[0] + " axis, " + rest.substr(2) + " (of q^" + rest[3] + ", q = |ω| / 100 °/s)";
      break;
  }
  return title + ", " + rest;
}

nlohmann::json coefficient_schema() {
  nlohmann::json groups = nlohmann::json::array(), coefficients = nlohmann::json::array();
  for (const CoefficientQuantity& q : coefficient_quantities())
    groups.push_back({{"key", q.key}, {"title", q.title}, {"unit", q.unit}});
  for (const Coefficient& c : model_coefficients(ImuModel{})) {
    const CoefficientQuantity& q = quantity_of(c.key);
    coefficients.push_back({{"key", c.key},
                            {"group", q.key},
                            {"title", coefficient_title(c.key)},
                            {"unit", q.unit},
                            {"optional", c.optional}});
  }
  return {{"groups", groups}, {"coefficients", coefficients}};
}

}  // namespace imucal
