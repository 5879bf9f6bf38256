// imucal compare: a calibration result against the truth of a simulated run, coefficient by
// coefficient.
#include "cli/commands.hpp"

#include <cstdio>
#include <fstream>
#include <string>

#include <nlohmann/json.hpp>

#include "core/coefficients.hpp"
#include "core/imu_model.hpp"
#include "estimators/direct_calibration.hpp"

namespace imucal::cli {

// Coefficient by coefficient: estimate, truth, error, sigma, error/sigma (simulated runs).
int run_compare(const std::string& model_path, const std::string& truth_path, const std::string& json_out) {
  const ImuModel est = read_imu_model_file(model_path);
  ImuModel truth = read_imu_model_file(truth_path);
  if (est.frame == "body" && truth.frame != "body") truth = direct::to_body_frame(truth);
  // Every key of the model (core/coefficients.hpp), the nonlinear terms, delays and proof masses
  // included where the estimate or the truth has them or the estimate states their uncertainty.
  const std::vector<Coefficient> estimated = model_coefficients(est), true_values = model_coefficients(truth);
  nlohmann::json rows = nlohmann::json::array();
  std::printf("%-34s %14s %14s %12s %10s %7s\n", "coefficient", "estimate", "truth", "error", "sigma", "err/sig");
  for (std::size_t i = 0; i < estimated.size(); ++i) {
    const Coefficient& e = estimated[i];
    const double t = true_values[i].value;
    if (e.optional && e.value == 0.0 && t == 0.0 && e.sigma == 0.0) continue;
    const double err = e.value - t;
    // %g: a delay of 0.3 us and a bias of 2e-6 m/s^2 both keep their digits.
    std::printf("%-34s %14.7g %14.7g %12.4g %10.3g %7.2f\n", e.key.c_str(), e.value, t, err, e.sigma,
                e.sigma > 0 ? err / e.sigma : 0.0);
    rows.push_back({{"name", e.key}, {"estimate", e.value}, {"truth", t}, {"error", err}, {"sigma", e.sigma}});
  }
  if (!json_out.empty()) {
    std::ofstream out(json_out);
    if (!out) throw std::runtime_error(json_out + ": cannot write");
    out << nlohmann::json({{"frame", est.frame}, {"rows", rows}}).dump(1) << "\n";
  }
  return 0;
}

}  // namespace imucal::cli
