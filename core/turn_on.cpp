#include "core/turn_on.hpp"

#include <cmath>

#include <nlohmann/json.hpp>

#include "core/model_json.hpp"
#include "core/units.hpp"

namespace imucal {

using nlohmann::json;
using namespace model_json;

namespace {

Eigen::Vector3d transient(const Eigen::Vector3d& amplitude, const Eigen::Vector3d& tau_s, double since_on_s) {
  Eigen::Vector3d out = Eigen::Vector3d::Zero();
  if (since_on_s < 0.0) return out;
  for (int j = 0; j < 3; ++j)
    if (amplitude[j] != 0.0 && tau_s[j] > 0.0) out[j] = amplitude[j] * std::exp(-since_on_s / tau_s[j]);
  return out;
}

// One sensor's keys: bias repeatability in `bias_key` units, the transient and its time constants.
struct SensorKeys {
  const char* repeatability;
  const char* warm_up;
  double to_si;
};
constexpr SensorKeys kGyroKeys{"bias_repeatability_dph", "warm_up_dph", units::kDphToRadps};
constexpr SensorKeys kAccelKeys{"bias_repeatability_mps2", "warm_up_mps2", 1.0};

void read_sensor(const json& j, const std::string& where, const SensorKeys& k, bool is_sigma, Eigen::Vector3d& rep,
                 Eigen::Vector3d& warm, Eigen::Vector3d& tau) {
  ObjectReader r = section(j, where);
  rep = vec3(r, k.repeatability, k.to_si);
  warm = vec3(r, k.warm_up, k.to_si);
  tau = vec3(r, "warm_up_time_constant_s", 1.0);
  r.finish();
  for (int i = 0; i < 3; ++i) {
    const std::string at = "[" + std::to_string(i) + "]";
    if (rep[i] < 0.0) r.fail(where + "." + k.repeatability + at, "must not be negative (a 1-sigma)");
    if (tau[i] < 0.0) r.fail(where + ".warm_up_time_constant_s" + at, "must not be negative");
    if (!is_sigma && warm[i] != 0.0 && !(tau[i] > 0.0))
      r.fail(where + ".warm_up_time_constant_s" + at, std::string("must be positive where ") + k.warm_up + " is not zero");
  }
}

TurnOnTerms terms_from(const json& j, const std::string& where, bool is_sigma) {
  ObjectReader r = section(j, where);
  TurnOnTerms t;
  if (const json* g = r.get("gyro"))
    read_sensor(*g, r.at("gyro"), kGyroKeys, is_sigma, t.gyro_repeatability_radps, t.gyro_warm_up_radps,
                t.gyro_time_constant_s);
  if (const json* a = r.get("accel"))
    read_sensor(*a, r.at("accel"), kAccelKeys, is_sigma, t.accel_repeatability_mps2, t.accel_warm_up_mps2,
                t.accel_time_constant_s);
  // The value section holds its sigma; a sigma section holds no further one.
  if (!is_sigma) r.get("sigma");
  r.finish();
  return t;
}

json sensor_to(const SensorKeys& k, const Eigen::Vector3d& rep, const Eigen::Vector3d& warm, const Eigen::Vector3d& tau) {
  return {{k.repeatability, arr(rep, 1.0 / k.to_si)}, {k.warm_up, arr(warm, 1.0 / k.to_si)},
          {"warm_up_time_constant_s", arr(tau, 1.0)}};
}

json terms_to(const TurnOnTerms& t) {
  return {{"gyro", sensor_to(kGyroKeys, t.gyro_repeatability_radps, t.gyro_warm_up_radps, t.gyro_time_constant_s)},
          {"accel", sensor_to(kAccelKeys, t.accel_repeatability_mps2, t.accel_warm_up_mps2, t.accel_time_constant_s)}};
}

}  // namespace

Eigen::Vector3d TurnOnTerms::gyro_transient_radps(double since_on_s) const {
  return transient(gyro_warm_up_radps, gyro_time_constant_s, since_on_s);
}

Eigen::Vector3d TurnOnTerms::accel_transient_mps2(double since_on_s) const {
  return transient(accel_warm_up_mps2, accel_time_constant_s, since_on_s);
}

TurnOnSection turn_on_from_json(const json& j, const std::string& where) {
  TurnOnSection s;
  s.value = terms_from(j, where, false);
  if (j.contains("sigma")) s.sigma = terms_from(j.at("sigma"), where + ".sigma", true);
  return s;
}

std::optional<TurnOnSection> turn_on_of(const ImuModel& model) {
  if (model.extra_json.empty()) return std::nullopt;
  const json extra = json::parse(model.extra_json);
  if (!extra.contains("turn_on")) return std::nullopt;
  return turn_on_from_json(extra.at("turn_on"), "turn_on");
}

void set_turn_on(ImuModel& model, const TurnOnSection& section) {
  json extra = model.extra_json.empty() ? json::object() : json::parse(model.extra_json);
  json j = terms_to(section.value);
  if (section.sigma) j["sigma"] = terms_to(*section.sigma);
  extra["turn_on"] = j;
  model.extra_json = extra.dump();
}

}  // namespace imucal
