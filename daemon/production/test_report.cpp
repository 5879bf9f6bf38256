#include "daemon/production/test_report.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <map>
#include <set>
#include <string>

namespace imucal::daemon {

using nlohmann::json;

TemperatureSummary summarize_temperatures(const std::vector<TempSample>& temps) {
  TemperatureSummary s;
  if (temps.empty()) return s;
  s.chamber_min_C = s.imu_min_C = std::numeric_limits<double>::infinity();
  s.chamber_max_C = s.imu_max_C = -std::numeric_limits<double>::infinity();
  for (const TempSample& t : temps) {
    const double imu = (t.gyro_C.sum() + t.accel_C.sum()) / 6.0;
    s.chamber_min_C = std::min(s.chamber_min_C, t.chamber_C);
    s.chamber_max_C = std::max(s.chamber_max_C, t.chamber_C);
    s.imu_min_C = std::min(s.imu_min_C, imu);
    s.imu_max_C = std::max(s.imu_max_C, imu);
    s.chamber_mean_C += t.chamber_C;
    s.imu_mean_C += imu;
  }
  s.samples = static_cast<int>(temps.size());
  s.chamber_mean_C /= s.samples;
  s.imu_mean_C /= s.samples;
  return s;
}

namespace {

const char* kStandard952 = "IEEE Std 952 (single-axis interferometric fiber optic gyros)";
const char* kStandard1293 = "IEEE Std 1293 (linear, single-axis, nongyroscopic accelerometers)";

json figure(const std::string& key, const std::string& name, double value, double u, const std::string& unit) {
  return {{"key", key}, {"name", name}, {"value", value}, {"u", u}, {"unit", unit}};
}

json pair_figure(const std::string& key, const std::string& name, const json& pair, const std::string& unit) {
  return figure(key, name, pair.at(0).get<double>(), pair.at(1).get<double>(), unit);
}

// The rate-steps test: per gyro its scale factors, asymmetry, IEEE 952 nonlinearity and fitted
// nonlinear terms; conditions the rates.
json rate_steps_test(const json& r) {
  json figures = json::array();
  std::set<double> rates;
  double full_scale = 0;
  for (const json& a : r.at("rate_steps").at("axes")) {
    const std::string ax = a.at("axis");
    const std::string g = "gyro " + ax;
    figures.push_back(pair_figure("gyro.bias_dph." + ax, g + " bias", a.at("bias_dph"), "deg/h"));
    figures.push_back(pair_figure("gyro.scale_pos_ppm." + ax, g + " scale factor error, positive rates", a.at("scale_pos_ppm"), "ppm"));
    figures.push_back(pair_figure("gyro.scale_neg_ppm." + ax, g + " scale factor error, negative rates", a.at("scale_neg_ppm"), "ppm"));
    figures.push_back(pair_figure("gyro.asymmetry_ppm." + ax, g + " scale factor asymmetry", a.at("asymmetry_ppm"), "ppm"));
    figures.push_back(pair_figure("gyro.nonlinearity_ppm_fs." + ax, g + " scale factor nonlinearity (largest deviation from the line)",
                                  a.at("nonlinearity_ppm_fs"), "ppm of full scale"));
    int k = 1;
    for (const json& c : a.at("scale_nonlinear_ppm")) {
      figures.push_back(pair_figure("gyro.scale_nonlinear_ppm." + ax + ".c" + std::to_string(k),
                                    g + " nonlinear term c" + std::to_string(k) + " (per (|rate| / 100 deg/s)^" + std::to_string(k) + ")",
                                    c, "ppm"));
      ++k;
    }
    full_scale = std::max(full_scale, a.value("full_scale_dps", 0.0));
    for (const json& st : a.at("steps")) rates.insert(std::abs(st.at("rate_dps").get<double>()));
  }
  std::vector<double> ladder(rates.begin(), rates.end());
  for (double& v : ladder) v = std::round(v * 100.0) / 100.0;
  ladder.erase(std::unique(ladder.begin(), ladder.end()), ladder.end());
  return {{"test", "rate-steps"}, {"title", "Scale factor, asymmetry and nonlinearity over rate steps"},
          {"standard", kStandard952},
          {"conditions", {{"rates_dps", ladder}, {"directions", "each rate positive and negative"}, {"full_scale_dps", full_scale}}},
          {"figures", figures}};
}

// The tumble: every coefficient its model estimated (accelerometers and the gyros' bias and
// g-sensitivity); conditions the positions.
json tumble_test(const json& r) {
  json figures = json::array();
  for (const auto& [key, pair] : r.at("estimates").items()) {
    const bool ours = key.rfind("accel.bias", 0) == 0 || key.rfind("accel.scale", 0) == 0 || key.rfind("accel.k2", 0) == 0 ||
                      key.rfind("accel.k3", 0) == 0 || key.rfind("accel.misalignment", 0) == 0 ||
                      key.rfind("gyro.bias", 0) == 0 || key.rfind("gyro.g_sensitivity", 0) == 0;
    if (!ours || !pair.is_array()) continue;
    figures.push_back(pair_figure(key, key, pair, ""));
  }
  const json& t = r.at("tumble");
  return {{"test", "tumble"}, {"title", "Multipoint tumble: bias, scale factor, K2, K3, misalignment; gyro g-sensitivity"},
          {"standard", kStandard1293},
          {"conditions", {{"positions", t.at("positions").size()},
                          {"accel_residual_rms_ug", t.at("accel_residual_rms_ug")},
                          {"gyro_residual_rms_dph", t.at("gyro_residual_rms_dph")}}},
          {"figures", figures}};
}

std::string channel_name(const json& c) {
  return std::string(c.at("sensor") == "gyro" ? "gyro " : "accelerometer ") + c.at("axis").get<std::string>();
}
std::string channel_unit(const json& c) { return c.at("unit") == "dph" ? "deg/h" : "ug"; }

json warm_up_test(const json& r) {
  const json& w = r.at("warm_up");
  json figures = json::array(), band = json::object();
  for (const json& c : w.at("channels")) {
    const std::string name = channel_name(c), key = c.at("sensor").get<std::string>() + "." + c.at("axis").get<std::string>();
    band[name] = c.at("band");
    if (!c.at("detected").get<bool>()) {
      figures.push_back({{"key", "warm_up." + key}, {"name", name + " warm-up transient"}, {"value", nullptr}, {"u", nullptr},
                         {"unit", channel_unit(c)}, {"note", "no transient above the noise"}});
      continue;
    }
    figures.push_back(pair_figure("warm_up." + key + ".amplitude", name + " transient at power-on", c.at("amplitude"), channel_unit(c)));
    figures.push_back(pair_figure("warm_up." + key + ".time_constant_s", name + " time constant", c.at("time_constant_s"), "s"));
    figures.push_back(pair_figure("warm_up." + key + ".settle_time_s", name + " time to settle within the band", c.at("settle_time_s"), "s"));
  }
  return {{"test", "warm-up"}, {"title", "Warm-up: the bias transient from power-on"}, {"standard", kStandard952},
          {"conditions", {{"duration_s", w.at("duration_s")}, {"orientation", "one static from power-on"}, {"band", band}}},
          {"figures", figures}};
}

json repeatability_test(const json& r) {
  const json& rep = r.at("repeatability");
  json figures = json::array();
  for (const json& c : rep.at("channels")) {
    json f = pair_figure(c.at("sensor").get<std::string>() + ".bias_repeatability." + c.at("axis").get<std::string>(),
                         channel_name(c) + " turn-on to turn-on bias repeatability (1 sigma)", c.at("repeatability"), channel_unit(c));
    f["interval_68"] = c.at("interval_68");
    f["interval_997"] = c.at("interval_997");
    figures.push_back(f);
  }
  double static_s = 0;
  for (const json& t : rep.at("turn_ons")) static_s += t.at("duration_s").get<double>();
  const auto n = rep.at("turn_ons").size();
  return {{"test", "repeatability"}, {"title", "Turn-on to turn-on bias repeatability"}, {"standard", kStandard952},
          {"conditions", {{"power_ons", n}, {"static_per_power_on_s", n ? static_s / static_cast<double>(n) : 0.0},
                          {"uncertainty", "half the 68.3 % chi-square interval of a standard deviation from the power-ons"}}},
          {"figures", figures}};
}

// Any other stage: the coefficients its model estimated.
json calibration_test(const std::string& stage, const json& r) {
  json figures = json::array();
  const json estimates = r.value("estimates", json::object());  // named: items() of a temporary dangles
  for (const auto& [key, pair] : estimates.items())
    if (pair.is_array() && pair.size() == 2 && pair.at(1).is_number() && pair.at(1).get<double>() > 0)
      figures.push_back(pair_figure(key, key, pair, ""));
  return {{"test", stage}, {"title", "Calibration stage " + stage}, {"standard", "the method's stage (docs/calibration.md)"},
          {"conditions", {{"source", r.value("source", "")}}}, {"figures", figures}};
}

}  // namespace

json test_report_json(const json& detail, const json& bench, const TemperatureSummary& t) {
  json tests = json::array();
  const json results = detail.value("results", json::object());
  for (const auto& [stage, r] : results.items()) {
    if (!r.is_object() || r.value("status", "") != "done") continue;
    if (stage == "rate-steps" && r.contains("rate_steps")) tests.push_back(rate_steps_test(r));
    else if (stage == "tumble" && r.contains("tumble")) tests.push_back(tumble_test(r));
    else if (stage == "warm-up" && r.contains("warm_up")) tests.push_back(warm_up_test(r));
    else if (stage == "repeatability" && r.contains("repeatability")) tests.push_back(repeatability_test(r));
    else if (r.contains("estimates")) tests.push_back(calibration_test(stage, r));
  }
  // The verdict per figure where the part number limits it (acceptance limits are on the model's keys).
  const json verdict = detail.value("verdict", json(nullptr));
  std::map<std::string, json> judged;
  if (verdict.is_object())
    for (const json& c : verdict.value("coefficients", json::array())) judged[c.at("key").get<std::string>()] = c;
  for (json& test : tests)
    for (json& f : test.at("figures")) {
      const auto it = judged.find(f.at("key").get<std::string>());
      if (it == judged.end()) continue;
      f["limit_value"] = it->second.value("limit_value", json(nullptr));
      f["limit_sigma"] = it->second.value("limit_sigma", json(nullptr));
      f["pass"] = it->second.at("pass");
      f["reason"] = it->second.value("reason", "");
    }
  // A FAIL names what failed: each coefficient outside its limits, or limited and not determined
  // (which no test lists among its figures).
  json failed = json::array();
  for (const auto& [key, c] : judged)
    if (!c.at("pass").get<bool>())
      failed.push_back({{"key", key}, {"value", c.value("value", json(nullptr))}, {"sigma", c.value("sigma", json(nullptr))},
                        {"limit_value", c.value("limit_value", json(nullptr))},
                        {"limit_sigma", c.value("limit_sigma", json(nullptr))}, {"reason", c.value("reason", "")}});
  const json spec = detail.value("spec", json::object());
  json temperatures = nullptr;
  if (t.samples > 0)
    temperatures = {{"samples", t.samples},
                    {"chamber_C", {{"min", t.chamber_min_C}, {"mean", t.chamber_mean_C}, {"max", t.chamber_max_C}}},
                    {"imu_C", {{"min", t.imu_min_C}, {"mean", t.imu_mean_C}, {"max", t.imu_max_C}}}};
  return {{"format", "imucal-test-report/1"},
          {"campaign", {{"id", detail.at("id")}, {"name", detail.value("name", "")}, {"program", detail.value("program", "")},
                        {"state", detail.value("state", "")}, {"started", detail.value("started", json(nullptr))},
                        {"ended", detail.value("ended", json(nullptr))}}},
          {"unit", {{"serial", detail.value("imu_serial", json(nullptr))}, {"identity", detail.value("imu", json(nullptr))}}},
          {"conditions", {{"duration_s", detail.value("duration_s", json(nullptr))},
                          {"program_time_s", detail.value("program_time_s", json(nullptr))},
                          {"rate_hz", spec.value("rate_hz", json(nullptr))},
                          {"frames", detail.value("frames", json(nullptr))},
                          {"gravity", bench.value("gravity", json(nullptr))},
                          {"temperatures", temperatures},
                          {"simulated", bench.value("simulated", false)}}},
          {"tests", tests},
          {"verdict", verdict.is_object() ? json{{"part_number", verdict.value("part_number", "")},
                                                 {"pass", verdict.at("pass")}, {"failures", verdict.value("failures", 0)},
                                                 {"failed", failed}}
                                          : json(nullptr)}};
}

}  // namespace imucal::daemon
