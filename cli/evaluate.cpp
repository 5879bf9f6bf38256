// imucal evaluate: models judged by free-inertial navigation on an evaluate run (the Schuler test).
#include "cli/commands.hpp"

#include <cstdio>
#include <fstream>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "core/imu_model.hpp"
#include "core/units.hpp"
#include "estimators/evaluate.hpp"
#include "pipeline/pipeline.hpp"
#include "storage/run_db.hpp"

namespace imucal::cli {

int run_evaluate(const std::string& db_path, const std::vector<std::string>& models, const std::string& out_path) {
  const auto db = storage::RunDb::open(db_path);
  const RecordingMeta meta = db.meta();
  nlohmann::json report = {{"db", db_path}, {"variants", nlohmann::json::array()}};
  double base_tilt = 0, base_coning = 0;
  for (std::size_t i = 0; i < models.size(); ++i) {
    std::string name = "variant-" + std::to_string(i + 1), path = models[i];
    if (const auto eq = path.find('='); eq != std::string::npos) {
      name = path.substr(0, eq);
      path = path.substr(eq + 1);
    }
    const ImuModel model = read_imu_model_file(path);
    const evaluate::Result r = pipeline::evaluate_recording(meta, pipeline::RunDbSource(db), model);
    nlohmann::json segs = nlohmann::json::array();
    for (const auto& s : r.segments)
      segs.push_back({{"name", s.name}, {"kind", s.kind}, {"t0_s", s.t0_s}, {"t1_s", s.t1_s},
                      {"schuler_amplitude_e_mps", s.schuler_amplitude_e_mps},
                      {"schuler_amplitude_n_mps", s.schuler_amplitude_n_mps},
                      {"implied_accel_error_mps2", s.implied_accel_error_mps2},
                      {"implied_gyro_drift_dph", s.implied_gyro_drift_radps * units::kRadpsToDph},
                      {"max_velocity_error_mps", s.max_velocity_error_mps},
                      {"max_position_error_m", s.max_position_error_m}});
    if (i == 0) {
      base_tilt = r.tilt_amplitude_mps;
      base_coning = r.coning_amplitude_mps;
    }
    auto ratio = [](double base, double v) { return v > 0 ? base / v : 0.0; };
    report["variants"].push_back({{"name", name},
                                  {"model", path},
                                  {"tilt_schuler_amplitude_mps", r.tilt_amplitude_mps},
                                  {"coning_schuler_amplitude_mps", r.coning_amplitude_mps},
                                  {"implied_accel_error_mps2", r.implied_accel_error_mps2},
                                  {"implied_gyro_drift_dph", r.implied_gyro_drift_radps * units::kRadpsToDph},
                                  {"tilt_improvement_over_first", ratio(base_tilt, r.tilt_amplitude_mps)},
                                  {"coning_improvement_over_first", ratio(base_coning, r.coning_amplitude_mps)},
                                  {"segments", segs}});
    std::printf("%-12s tilt Schuler amplitude %.5f m/s (accel error %.2e m/s^2), coning %.5f m/s (drift %.5f deg/h)\n",
                name.c_str(), r.tilt_amplitude_mps, r.implied_accel_error_mps2, r.coning_amplitude_mps,
                r.implied_gyro_drift_radps * units::kRadpsToDph);
  }
  std::ofstream out(out_path);
  if (!out) throw std::runtime_error(out_path + ": cannot write");
  out << report.dump(1) << "\n";
  return 0;
}

}  // namespace imucal::cli
