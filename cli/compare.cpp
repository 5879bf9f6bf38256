// imucal compare: a calibration result against the truth of a simulated run, coefficient by
// coefficient.
#include "cli/commands.hpp"

#include <cstdio>
#include <fstream>
#include <string>

#include <nlohmann/json.hpp>

#include "core/imu_model.hpp"
#include "estimators/truth_comparison.hpp"

namespace imucal::cli {

// Coefficient by coefficient: estimate, truth, error, sigma, error/sigma (simulated runs), the
// truth in the estimate's frame (estimators/truth_comparison.hpp: the daemon's results page makes
// the same comparison).
int run_compare(const std::string& model_path, const std::string& truth_path, const std::string& json_out) {
  const ImuModel est = read_imu_model_file(model_path);
  const TruthComparison cmp = compare_with_truth(est, read_imu_model_file(truth_path));
  nlohmann::json rows = nlohmann::json::array();
  if (cmp.converted) std::printf("(the truth, written in the %s frame, turned into the %s frame)\n", cmp.truth_frame.c_str(), cmp.frame.c_str());
  std::printf("%-34s %14s %14s %12s %10s %7s\n", "coefficient", "estimate", "truth", "error", "sigma", "err/sig");
  for (const TruthComparisonRow& r : cmp.rows) {
    // Every key of the model (core/coefficients.hpp), the nonlinear terms, delays and proof masses
    // included where the estimate or the truth has them or the estimate states their uncertainty.
    if (r.optional && r.estimate == 0.0 && r.truth == 0.0 && r.sigma == 0.0) continue;
    if (r.by_definition) {
      std::printf("%-34s %14s\n", r.key.c_str(), ("0 by definition of the " + cmp.frame + " frame").c_str());
      rows.push_back({{"name", r.key}, {"by_definition", true}});
      continue;
    }
    // %g: a delay of 0.3 us and a bias of 2e-6 m/s^2 both keep their digits.
    std::printf("%-34s %14.7g %14.7g %12.4g %10.3g %7.2f\n", r.key.c_str(), r.estimate, r.truth, r.error, r.sigma,
                r.error_over_sigma.value_or(0.0));
    rows.push_back({{"name", r.key}, {"estimate", r.estimate}, {"truth", r.truth}, {"error", r.error}, {"sigma", r.sigma}});
  }
  if (!json_out.empty()) {
    std::ofstream out(json_out);
    if (!out) throw std::runtime_error(json_out + ": cannot write");
    out << nlohmann::json({{"frame", cmp.frame}, {"rows", rows}}).dump(1) << "\n";
  }
  return 0;
}

}  // namespace imucal::cli
