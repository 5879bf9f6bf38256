#include "daemon/production/acceptance.hpp"

#include <algorithm>
#include <cmath>
#include <set>
#include <stdexcept>

#include "core/imu_model.hpp"
#include "core/json_reader.hpp"

namespace imucal::daemon {

using nlohmann::json;

namespace {

void flatten(const json& value, const std::string& prefix, std::vector<std::pair<std::string, double>>& out) {
  static constexpr const char* kAxes[] = {"x", "y", "z"};
  if (value.is_number()) {
    out.emplace_back(prefix, value.get<double>());
  } else if (value.is_array() && value.size() == 3 &&
             std::all_of(value.begin(), value.end(), [](const json& v) { return v.is_number(); })) {
    for (std::size_t i = 0; i < 3; ++i) out.emplace_back(prefix + "." + kAxes[i], value[i].get<double>());
  } else if (value.is_object()) {
    for (const auto& [key, v] : value.items())
      if (!key.empty() && key.front() != '_') flatten(v, prefix + "." + key, out);
  }
}

bool is_noise(const std::string& key) { return key.find(".noise.") != std::string::npos; }

// Every flat name a model can carry: the names of the writer's own output for a model with every
// optional term (the nonlinear ones are written only when not zero), so a limit on a coefficient
// that does not exist (a typo) is refused, not silently never applied.
const std::set<std::string>& known_keys() {
  static const std::set<std::string> keys = [] {
    ImuModel every;
    every.gyro.scale_nonlinear.setConstant(1.0);
    every.gyro.g_sensitivity_radps_per_g.setConstant(1.0);
    every.accel.k2_per_g.setConstant(1.0);
    every.accel.k3_per_g2.setConstant(1.0);
    std::set<std::string> k;
    for (const auto& [name, v] : flat_coefficients(json::parse(imu_model_to_json_text(every)))) k.insert(name);
    return k;
  }();
  return keys;
}

// The most specific limit for a flat coefficient name: the key itself, else its nearest group.
const Limit* limit_for(const PartLimits& p, const std::string& key) {
  for (std::string k = key;;) {
    if (const auto it = p.limits.find(k); it != p.limits.end()) return &it->second;
    const auto dot = k.rfind('.');
    if (dot == std::string::npos) return nullptr;
    k.resize(dot);
  }
}

std::map<std::string, double> as_map(const std::vector<std::pair<std::string, double>>& v) {
  return {v.begin(), v.end()};
}

std::optional<double> find(const std::map<std::string, double>& m, const std::string& key) {
  const auto it = m.find(key);
  return it == m.end() ? std::nullopt : std::optional<double>(it->second);
}

json number_or_null(std::optional<double> v) { return v ? json(*v) : json(nullptr); }

std::string short_number(double v) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.6g", v);
  return buf;
}

}  // namespace

std::vector<std::pair<std::string, double>> flat_coefficients(const json& model) {
  std::vector<std::pair<std::string, double>> out;
  for (const char* triad : {"gyro", "accel"})
    if (model.is_object() && model.contains(triad)) flatten(model.at(triad), triad, out);
  return out;
}

bool determined(const std::string& key, double value, std::optional<double> sigma) {
  if (is_noise(key)) return value > 0;
  return sigma && *sigma > 0 && std::isfinite(*sigma);
}

namespace {

// A bound of a limit: absent, or a positive number.
std::optional<double> read_bound(ObjectReader& r, const char* field) {
  const auto v = r.number(field);
  if (v && !(*v > 0)) r.fail(r.at(field) + " must be a positive number in the key's unit");
  return v;
}

// One coefficient key's limit (at `at` in the file): max_abs, max_sigma or both; a noise term has
// no sigma to limit. Apart from limits_from_json: the two loops with this inside made clang-tidy's
// optional-access analysis of it take from 10 s to over 100 s of CPU, as the run fell.
Limit read_limit(const json& spec, const std::string& key, const std::string& at) {
  ObjectReader r(spec, at, ObjectReader::ThrowAtFirst{""});
  Limit limit;
  limit.max_abs = read_bound(r, "max_abs");
  limit.max_sigma = read_bound(r, "max_sigma");
  r.finish();
  if (!limit.max_abs && !limit.max_sigma) throw std::invalid_argument(at + " has neither max_abs nor max_sigma");
  if (limit.max_sigma && is_noise(key)) throw std::invalid_argument(at + ": noise terms carry no sigma; give max_abs only");
  return limit;
}

}  // namespace

std::map<std::string, PartLimits> limits_from_json(const json& file) {
  // The one strict reader (core/json_reader.hpp), throwing at the first problem.
  const ObjectReader::ThrowAtFirst throwing{""};
  ObjectReader r(file, "limits", throwing);
  if (r.string("format") != std::string("imucal-limits/1")) r.fail("limits.format must be \"imucal-limits/1\"");
  r.get("comment");
  const json* parts_json = r.get("part_numbers");
  r.finish();
  const json parts = parts_json != nullptr ? *parts_json : json::object();
  if (!parts.is_object()) throw std::invalid_argument("limits: part_numbers must be an object of part numbers");
  std::map<std::string, PartLimits> out;
  for (const auto& [part_number, entries] : parts.items()) {
    const std::string where = "limits.part_numbers[\"" + part_number + "\"]";
    if (part_number.empty() || part_number.size() > 2000) throw std::invalid_argument(where + ": a part number needs 1 to 2000 characters");
    if (!entries.is_object()) throw std::invalid_argument(where + " must be an object of coefficient keys");
    PartLimits p{part_number, {}};
    for (const auto& [key, spec] : entries.items()) {
      const std::string at = where + "[\"" + key + "\"]";
      // A key is a coefficient or a group of them: some known name equals it or starts with "key.".
      const auto& known = known_keys();
      const auto it = known.lower_bound(key);
      const bool exists = it != known.end() && (*it == key || it->rfind(key + ".", 0) == 0);
      if (!exists)
        throw std::invalid_argument(at + ": no coefficient of the model is named so (e.g. \"gyro.bias_dph\", "
                                         "\"gyro.bias_dph.x\", \"accel.misalignment_arcsec.yz\")");
      p.limits[key] = read_limit(spec, key, at);
    }
    out.emplace(part_number, std::move(p));
  }
  return out;
}

namespace {

// One limit as the file holds it: the bounds it has.
json limit_to_json(const Limit& l) {
  json spec = json::object();
  if (l.max_abs) spec["max_abs"] = *l.max_abs;
  if (l.max_sigma) spec["max_sigma"] = *l.max_sigma;
  return spec;
}

}  // namespace

json limits_to_json(const std::map<std::string, PartLimits>& limits) {
  json parts = json::object();
  for (const auto& [part_number, p] : limits) {
    json entries = json::object();
    for (const auto& [key, l] : p.limits) entries[key] = limit_to_json(l);
    parts[part_number] = entries;
  }
  return {{"format", "imucal-limits/1"}, {"part_numbers", parts}};
}

std::set<std::string> changed_part_numbers(const json& before, const json& after) {
  const auto parts = [](const json& doc) {
    return doc.is_object() && doc.contains("part_numbers") && doc.at("part_numbers").is_object() ? doc.at("part_numbers")
                                                                                                  : json::object();
  };
  const json a = parts(before), b = parts(after);
  std::set<std::string> changed;
  for (const auto& [part_number, limits] : a.items())
    if (!b.contains(part_number) || b.at(part_number) != limits) changed.insert(part_number);
  for (const auto& [part_number, limits] : b.items())
    if (!a.contains(part_number)) changed.insert(part_number);
  return changed;
}

json verdict_json(const json& model, const PartLimits& limits, const std::string& source) {
  const auto sigmas = as_map(model.is_object() && model.contains("sigma") ? flat_coefficients(model.at("sigma"))
                                                                           : std::vector<std::pair<std::string, double>>{});
  json rows = json::array();
  int failures = 0;
  for (const auto& [key, value] : flat_coefficients(model)) {
    const Limit* l = limit_for(limits, key);
    if (!l) continue;
    const std::optional<double> sigma = find(sigmas, key);
    std::vector<std::string> why;
    if (!determined(key, value, sigma)) {
      why.push_back("not determined by this run");
    } else {
      if (l->max_abs && std::abs(value) > *l->max_abs)
        why.push_back("|value| " + short_number(std::abs(value)) + " > limit " + short_number(*l->max_abs));
      // A noise term is determined without a sigma (it carries none): a group's sigma limit
      // ({"gyro": {"max_sigma": ...}}) does not apply to it.
      if (l->max_sigma && sigma && *sigma > *l->max_sigma)
        why.push_back("sigma " + short_number(*sigma) + " > limit " + short_number(*l->max_sigma));
    }
    std::string reason;
    for (const auto& w : why) reason += (reason.empty() ? "" : "; ") + w;
    if (!why.empty()) ++failures;
    rows.push_back({{"key", key},
                    {"value", value},
                    {"sigma", number_or_null(sigma)},
                    {"limit_value", number_or_null(l->max_abs)},
                    {"limit_sigma", number_or_null(l->max_sigma)},
                    {"pass", why.empty()},
                    {"reason", reason}});
  }
  return {{"part_number", limits.part_number},
          {"pass", failures == 0},
          {"failures", failures},
          {"limits", source},
          {"coefficients", rows}};
}

json verdict_or_null(const json& model, const std::string& part_number, const AcceptanceLimits& limits) {
  if (!model.is_object() || part_number.empty()) return nullptr;
  const auto it = limits.parts.find(part_number);
  return it == limits.parts.end() ? json(nullptr) : verdict_json(model, it->second, limits.source);
}

json compare_json(const json& model_a, const json& model_b) {
  auto sigmas_of = [](const json& m) {
    return as_map(m.is_object() && m.contains("sigma") ? flat_coefficients(m.at("sigma"))
                                                       : std::vector<std::pair<std::string, double>>{});
  };
  const auto values_b = as_map(flat_coefficients(model_b));
  const auto sigmas_a = sigmas_of(model_a), sigmas_b = sigmas_of(model_b);
  json rows = json::array();
  int significant = 0;
  for (const auto& [key, a] : flat_coefficients(model_a)) {
    const auto b = find(values_b, key);
    if (!b) continue;
    const auto sa = find(sigmas_a, key), sb = find(sigmas_b, key);
    const bool da = determined(key, a, sa), db = determined(key, *b, sb);
    if (!da && !db) continue;
    json row = {{"key", key}, {"a", a}, {"sigma_a", number_or_null(sa)}, {"b", *b},
                {"sigma_b", number_or_null(sb)}, {"difference", *b - a}};
    if (da && db && sa && sb && !is_noise(key)) {  // (determined and not noise: both have a sigma)
      const double combined = std::hypot(*sa, *sb);
      const double in_sigmas = (*b - a) / combined;
      row["combined_sigma"] = combined;
      row["in_sigmas"] = in_sigmas;
      row["significant"] = std::abs(in_sigmas) > 3.0;
      if (std::abs(in_sigmas) > 3.0) ++significant;
    } else {
      // Noise terms carry no sigma; a coefficient only one run determined has no comparison.
      row["combined_sigma"] = nullptr;
      row["in_sigmas"] = nullptr;
      row["significant"] = nullptr;
    }
    rows.push_back(std::move(row));
  }
  return {{"coefficients", rows}, {"significant", significant}};
}

json repeatability_json(const std::vector<json>& models) {
  std::map<std::string, std::vector<double>> values;
  std::vector<std::string> order;
  for (const json& m : models) {
    const auto sigmas = as_map(m.is_object() && m.contains("sigma") ? flat_coefficients(m.at("sigma"))
                                                                     : std::vector<std::pair<std::string, double>>{});
    for (const auto& [key, v] : flat_coefficients(m)) {
      if (!determined(key, v, find(sigmas, key))) continue;
      if (!values.count(key)) order.push_back(key);
      values[key].push_back(v);
    }
  }
  json out = json::object();
  for (const std::string& key : order) {
    const auto& v = values.at(key);
    if (v.size() < 2) continue;
    double mean = 0;
    for (double x : v) mean += x;
    mean /= static_cast<double>(v.size());
    double ss = 0;
    for (double x : v) ss += (x - mean) * (x - mean);
    out[key] = {{"n", v.size()}, {"mean", mean}, {"std", std::sqrt(ss / static_cast<double>(v.size() - 1))}};
  }
  return out;
}

}  // namespace imucal::daemon
