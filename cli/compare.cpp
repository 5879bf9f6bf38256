// imucal compare: a calibration result against the truth of a simulated run, coefficient by
// coefficient.
#include "cli/commands.hpp"

#include <cstdio>
#include <fstream>
#include <string>

#include <nlohmann/json.hpp>

#include "core/imu_model.hpp"
#include "core/units.hpp"
#include "estimators/direct_calibration.hpp"

namespace imucal::cli {

// Coefficient by coefficient: estimate, truth, error, sigma, error/sigma (simulated runs).
int run_compare(const std::string& model_path, const std::string& truth_path, const std::string& json_out) {
  const ImuModel est = read_imu_model_file(model_path);
  ImuModel truth = read_imu_model_file(truth_path);
  if (est.frame == "body" && truth.frame != "body") truth = direct::to_body_frame(truth);
  const ImuErrorSet sigma = est.sigma.value_or(ImuErrorSet{});
  nlohmann::json rows = nlohmann::json::array();
  std::printf("%-26s %14s %14s %12s %10s %7s\n", "coefficient", "estimate", "truth", "error", "sigma", "err/sig");
  auto row = [&](const std::string& name, double e, double t, double s, double scale) {
    const double err = (e - t) * scale, sig = s * scale;
    // %g: a delay of 0.3 us and a bias of 2e-6 m/s^2 both keep their digits.
    std::printf("%-26s %14.7g %14.7g %12.4g %10.3g %7.2f\n", name.c_str(), e * scale, t * scale, err, sig,
                sig > 0 ? err / sig : 0.0);
    rows.push_back({{"name", name}, {"estimate", e * scale}, {"truth", t * scale}, {"error", err}, {"sigma", sig}});
  };
  const char* ax[3] = {"x", "y", "z"};
  for (int j = 0; j < 3; ++j) {
    const std::string a = ax[j];
    row("gyro.bias_dph." + a, est.gyro.bias_radps[j], truth.gyro.bias_radps[j], sigma.gyro.bias_radps[j], units::kRadpsToDph);
    row("gyro.scale_pos_ppm." + a, est.gyro.scale_pos[j], truth.gyro.scale_pos[j], sigma.gyro.scale_pos[j], 1e6);
    row("gyro.scale_neg_ppm." + a, est.gyro.scale_neg[j], truth.gyro.scale_neg[j], sigma.gyro.scale_neg[j], 1e6);
    row("gyro.delay_us." + a, est.gyro.delay_s[j], truth.gyro.delay_s[j], sigma.gyro.delay_s[j], 1e6);
    row("accel.bias_mps2." + a, est.accel.bias_mps2[j], truth.accel.bias_mps2[j], sigma.accel.bias_mps2[j], 1.0);
    row("accel.scale_ppm." + a, est.accel.scale[j], truth.accel.scale[j], sigma.accel.scale[j], 1e6);
    row("accel.delay_us." + a, est.accel.delay_s[j], truth.accel.delay_s[j], sigma.accel.delay_s[j], 1e6);
    row("accel.lever_arm_y_mm." + a, est.accel.lever_arm_y_m[j], truth.accel.lever_arm_y_m[j], sigma.accel.lever_arm_y_m[j], 1e3);
    row("accel.lever_arm_z_mm." + a, est.accel.lever_arm_z_m[j], truth.accel.lever_arm_z_m[j], sigma.accel.lever_arm_z_m[j], 1e3);
  }
  for (const auto& [n, k] : kMisalignmentKeys) {
    row(std::string("gyro.misalignment_arcsec.") + n, est.gyro.misalignment_rad.*k, truth.gyro.misalignment_rad.*k,
        sigma.gyro.misalignment_rad.*k, units::kRadToArcsec);
    row(std::string("accel.misalignment_arcsec.") + n, est.accel.misalignment_rad.*k, truth.accel.misalignment_rad.*k,
        sigma.accel.misalignment_rad.*k, units::kRadToArcsec);
  }
  if (!json_out.empty()) {
    std::ofstream out(json_out);
    if (!out) throw std::runtime_error(json_out + ": cannot write");
    out << nlohmann::json({{"frame", est.frame}, {"rows", rows}}).dump(1) << "\n";
  }
  return 0;
}

}  // namespace imucal::cli
