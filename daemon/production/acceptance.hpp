// Acceptance of a unit's calibration (issue 17, docs/api.md "Units"): limits per part number, the
// verdict of a model against them, the comparison of two calibrations and a unit's repeatability.
// Pure functions of model JSON (imucal-imu-model/1), so the daemon's replies, the unit page and
// the certificate judge by one rule.
//
// Coefficients are named flat, as the history CSV and the browser's tables name them:
// "gyro.bias_dph.x", "accel.misalignment_arcsec.yz", "gyro.noise.arw_deg_rth".
#pragma once

#include <map>
#include <optional>
#include <set>
#include <string>
#include <utility>
#include <vector>

#include <nlohmann/json.hpp>

namespace imucal::daemon {

// The numeric coefficients of a model's triads by flat name, in the model's order. `sigma` of a
// result has the same shape, so flat_coefficients(model["sigma"]) names its sigmas alike.
std::vector<std::pair<std::string, double>> flat_coefficients(const nlohmann::json& model);

// A coefficient is determined by a run when the run gave it a positive sigma; noise terms carry no
// sigma and are determined when positive. A stage writes sigma 0 (or none) for what it carried
// over without estimating it (a direct-only run's delays, proof-mass offsets).
bool determined(const std::string& key, double value, std::optional<double> sigma);

// One limit: |value| <= max_abs and sigma <= max_sigma (either may be absent, not both).
struct Limit {
  std::optional<double> max_abs;
  std::optional<double> max_sigma;
};

// A part number's limits by key: a key names one coefficient ("gyro.bias_dph.x") or a group of
// them ("gyro.bias_dph": every axis); the most specific key applies.
struct PartLimits {
  std::string part_number;
  std::map<std::string, Limit> limits;
};

// The limits file (imucal-limits/1):
//   {"format": "imucal-limits/1",
//    "part_numbers": {"FOG-NAV-1": {"gyro.bias_dph": {"max_abs": 0.05, "max_sigma": 0.001}, ...}}}
// Throws std::invalid_argument naming the part number and key at fault (an unknown coefficient,
// a limit that is not a positive number, an unknown field).
std::map<std::string, PartLimits> limits_from_json(const nlohmann::json& file);
nlohmann::json limits_to_json(const std::map<std::string, PartLimits>& limits);

// The part numbers whose limits differ between two limits documents (imucal-limits/1 as
// limits_to_json writes them): added, removed or changed. Only their units' verdicts can change.
std::set<std::string> changed_part_numbers(const nlohmann::json& before, const nlohmann::json& after);

// The verdict of a model against a part number's limits:
//   {"part_number", "pass", "failures", "limits": source,
//    "coefficients": [{"key", "value", "sigma", "limit_value", "limit_sigma", "pass", "reason"}]}
// one entry per coefficient that has a limit; a coefficient with a limit that the run did not
// determine fails with reason "not determined by this run". `sigma` is null when there is none.
nlohmann::json verdict_json(const nlohmann::json& model, const PartLimits& limits, const std::string& source);

// The limits in force (the daemon's limits file) and where they came from.
struct AcceptanceLimits {
  std::map<std::string, PartLimits> parts;
  std::string source;
};
// The verdict of a run's model against its part number's limits; null when the run has no model,
// names no part number, or its part number has no limits.
nlohmann::json verdict_or_null(const nlohmann::json& model, const std::string& part_number,
                               const AcceptanceLimits& limits);

// Two calibrations side by side (b against a): per coefficient both values and sigmas, the
// difference b - a, the combined sigma sqrt(sa^2 + sb^2), the difference in combined sigmas and
// whether it is significant (beyond 3 combined sigmas). Coefficients neither run determined are
// left out; one determined by only one run is listed with "significant": null.
nlohmann::json compare_json(const nlohmann::json& model_a, const nlohmann::json& model_b);

// Each determined coefficient's spread over a unit's calibrations (oldest first), the turn-on to
// turn-on repeatability of IEEE Std 952 for the biases: {"key": {"n", "mean", "std"}} with the
// sample standard deviation over the n >= 2 runs that determined it.
nlohmann::json repeatability_json(const std::vector<nlohmann::json>& models);

}  // namespace imucal::daemon
