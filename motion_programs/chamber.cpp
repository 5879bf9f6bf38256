#include "motion_programs/chamber.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <sstream>
#include <stdexcept>

#include <nlohmann/json.hpp>

#include "core/json_reader.hpp"

namespace imucal::motion {

using nlohmann::json;

double ChamberProfile::setpoint_C(double t_s) const {
  const ChamberStep* s = step_at(t_s);
  if (!s) return start_C;
  if (t_s <= s->t0_s) return s->from_C;
  if (t_s >= s->t1_s) return s->to_C;
  return s->from_C + (s->to_C - s->from_C) * (t_s - s->t0_s) / (s->t1_s - s->t0_s);
}

const ChamberStep* ChamberProfile::step_at(double t_s) const {
  if (steps.empty()) return nullptr;
  auto it = std::upper_bound(steps.begin(), steps.end(), t_s, [](double t, const ChamberStep& s) { return t < s.t1_s; });
  if (it == steps.end()) return &steps.back();
  return &*it;
}

bool ramps_within(const ChamberProfile& profile, double t0_s, double t1_s) {
  return std::any_of(profile.steps.begin(), profile.steps.end(), [&](const ChamberStep& s) {
    return s.kind == "ramp" && s.t1_s > s.t0_s && s.from_C != s.to_C && s.t0_s < t1_s && s.t1_s > t0_s;
  });
}

ChamberProfile profile_of_changes(double start_C, const std::vector<SetpointChange>& changes, double end_s) {
  ChamberProfile p;
  p.name = "set-point changes";
  p.start_C = start_C;
  double t_s = 0.0, value_C = start_C;
  auto push = [&](const char* kind, double t1_s, double to_C) {
    if (t1_s <= t_s) return;
    const bool set = std::string(kind) == "set";
    p.steps.push_back({std::string(kind) + "-" + std::to_string(p.steps.size() + 1), kind, t_s, t1_s,
                       set ? to_C : value_C, to_C});
    t_s = t1_s;
    value_C = to_C;
  };
  for (std::size_t i = 0; i < changes.size(); ++i) {
    const SetpointChange& c = changes[i];
    const double next_s = i + 1 < changes.size() ? changes[i + 1].at_s : std::max(end_s, c.at_s);
    push("soak", c.at_s, value_C);  // what the change before reached holds until this one
    if (c.ramp_C_per_min <= 0.0) {
      // A step: the set point jumps (a change at the very end still sets what follows it).
      if (next_s > c.at_s) push("set", next_s, c.setpoint_C);
      else value_C = c.setpoint_C;
      continue;
    }
    const double rate_C_per_s = c.ramp_C_per_min / 60.0;
    const double ramp_s = std::min(next_s - c.at_s, std::abs(c.setpoint_C - value_C) / rate_C_per_s);
    push("ramp", c.at_s + ramp_s, value_C + std::copysign(rate_C_per_s * ramp_s, c.setpoint_C - value_C));
    push("soak", next_s, value_C);
  }
  return p;
}

std::vector<SetpointChange> changes_of(const ChamberProfile& profile) {
  std::vector<SetpointChange> out;
  for (const ChamberStep& s : profile.steps) {
    if (s.kind == "soak") continue;  // holds what the step before reached
    const double rate = s.kind == "ramp" && s.t1_s > s.t0_s ? std::abs(s.to_C - s.from_C) / (s.t1_s - s.t0_s) * 60.0 : 0.0;
    out.push_back({s.t0_s, s.to_C, rate});
  }
  return out;
}

ChamberProfile compile_chamber_profile(const std::string& json_text) {
  json j;
  try {
    j = json::parse(json_text);
  } catch (const json::parse_error& e) {
    throw std::invalid_argument(std::string("chamber profile: not valid JSON: ") + e.what());
  }
  const ObjectReader::ThrowAtFirst throwing{"chamber profile: "};
  ObjectReader r(j, "", throwing);
  ChamberProfile p;
  p.name = r.string("name").value_or("unnamed");
  r.get("comment");
  p.source_json = j.dump();
  p.start_C = r.required_number("start_C");
  const json* steps = r.get("steps", true);
  if (!steps->is_array() || steps->empty()) r.fail("steps must be a non-empty list");
  r.finish();
  double t = 0, sp = p.start_C;
  int index = 0;
  for (const json& st : *steps) {
    ObjectReader sr(st, "steps[" + std::to_string(index) + "]", throwing);
    ++index;
    const std::string type = sr.required_string("type");
    const std::string name = sr.string("name").value_or(type + "-" + std::to_string(index));
    const std::string where = "step " + std::to_string(index) + " '" + name + "'";
    const auto fail = [&](const std::string& what) { sr.fail(where + ": " + what); };
    const auto positive = [&](const char* key) {
      const double v = sr.required_number(key);
      if (v <= 0) fail(std::string(key) + " must be positive");
      return v;
    };
    ChamberStep s;
    s.name = name;
    s.kind = type;
    s.t0_s = t;
    if (type == "soak") {
      s.from_C = s.to_C = sp;
      s.t1_s = t + positive("duration_s");
    } else if (type == "ramp") {
      s.from_C = sp;
      s.to_C = sr.required_number("to_C");
      if (sr.has("rate_C_per_min") == sr.has("duration_s")) fail("give either \"rate_C_per_min\" or \"duration_s\"");
      double d;
      if (sr.has("rate_C_per_min")) {
        const double rate = sr.required_number("rate_C_per_min");
        if (rate <= 0) fail("rate_C_per_min must be positive (the direction follows from to_C)");
        d = std::abs(s.to_C - s.from_C) / rate * 60.0;
      } else {
        d = sr.required_number("duration_s");
      }
      if (d <= 0) fail("the ramp has no length (to_C equals the set point before it?)");
      s.t1_s = t + d;
    } else if (type == "set") {
      s.from_C = s.to_C = sr.required_number("to_C");
      s.t1_s = t + positive("duration_s");
    } else {
      fail("unknown type \"" + type + "\" (soak, ramp, set)");
    }
    sr.finish();
    t = s.t1_s;
    sp = s.to_C;
    p.steps.push_back(s);
  }
  return p;
}

std::vector<std::string> validate_chamber_profile(const ChamberProfile& p, const ChamberLimits& lim) {
  std::vector<std::string> problems;
  char buf[300];
  auto check_C = [&](const ChamberStep& s, double v) {
    if (v < lim.min_C || v > lim.max_C) {
      std::snprintf(buf, sizeof buf, "step '%s' (t=%.0f s): set point %.2f C outside the chamber's %.1f..%.1f C",
                    s.name.c_str(), s.t0_s, v, lim.min_C, lim.max_C);
      problems.emplace_back(buf);
    }
  };
  if (p.start_C < lim.min_C || p.start_C > lim.max_C) {
    std::snprintf(buf, sizeof buf, "start_C %.2f C outside the chamber's %.1f..%.1f C", p.start_C, lim.min_C, lim.max_C);
    problems.emplace_back(buf);
  }
  for (const ChamberStep& s : p.steps) {
    check_C(s, s.from_C);
    check_C(s, s.to_C);
    if (s.kind == "ramp") {
      const double rate = std::abs(s.to_C - s.from_C) / (s.t1_s - s.t0_s) * 60.0;
      if (rate > lim.max_ramp_C_per_min * (1 + 1e-9)) {
        std::snprintf(buf, sizeof buf, "step '%s' (t=%.0f s): ramp %.3f C/min faster than the chamber's %.3f C/min",
                      s.name.c_str(), s.t0_s, rate, lim.max_ramp_C_per_min);
        problems.emplace_back(buf);
      }
    }
  }
  return problems;
}

namespace {

json soak(const std::string& name, double minutes) {
  return {{"type", "soak"}, {"name", name}, {"duration_s", minutes * 60.0}};
}
json ramp(const std::string& name, double to_C, double rate_C_per_min) {
  return {{"type", "ramp"}, {"name", name}, {"to_C", to_C}, {"rate_C_per_min", rate_C_per_min}};
}

// 12 h over 15..35 C: heating and cooling through the whole range at 0.25, 0.5 and 1 C/min,
// soaks at both ends long enough for the sensors to settle (rest at the ends of the T axis),
// and a return to 25 C. Set points sit 1 C outside the range, so that the lagging sensors
// still reach 15 and 35 C within the soaks.
json thermal_profile() {
  json steps = json::array();
  double sp_C = 25.0, minutes = 0.0;
  auto add_soak = [&](const std::string& name, double min) {
    steps.push_back(soak(name, min));
    minutes += min;
  };
  auto add_ramp = [&](const std::string& name, double to_C, double rate) {
    steps.push_back(ramp(name, to_C, rate));
    minutes += std::abs(to_C - sp_C) / rate;
    sp_C = to_C;
  };
  add_soak("soak-25", 20);
  add_ramp("cool-0.5", 14, 0.5);
  add_soak("soak-14-a", 50);
  add_ramp("heat-0.25", 36, 0.25);
  add_soak("soak-36-a", 50);
  add_ramp("cool-1.0", 14, 1.0);
  add_soak("soak-14-b", 50);
  add_ramp("heat-1.0", 36, 1.0);
  add_soak("soak-36-b", 50);
  add_ramp("cool-0.25", 14, 0.25);
  add_soak("soak-14-c", 40);
  add_ramp("heat-0.5", 36, 0.5);
  add_soak("soak-36-c", 40);
  add_ramp("to-25", 25, 0.5);
  // The rest of the 12 h at 25 C.
  add_soak("soak-25-end", std::max(10.0, 720.0 - minutes));
  return {{"name", "thermal"},
          {"comment", "Stage 2 (seed ch. 3): about 12 h covering the (T, dT/dt) plane over 15..35 C"},
          {"start_C", 25.0},
          {"steps", steps}};
}

// About 2 h, for quick checks: one cooling and one heating pass at 1 C/min.
json thermal_short_profile() {
  json steps = json::array();
  steps.push_back(soak("soak-25", 10));
  steps.push_back(ramp("cool-1.0", 15, 1.0));
  steps.push_back(soak("soak-15", 30));
  steps.push_back(ramp("heat-1.0", 35, 1.0));
  steps.push_back(soak("soak-35", 30));
  steps.push_back(ramp("to-25", 25, 1.0));
  return {{"name", "thermal-short"},
          {"comment", "A 2-hour version of thermal for quick checks (too little coverage for a real model)"},
          {"start_C", 25.0},
          {"steps", steps}};
}

}  // namespace

std::vector<std::string> builtin_chamber_names() { return {"thermal", "thermal-short"}; }

bool is_builtin_chamber(const std::string& name) {
  const auto names = builtin_chamber_names();
  return std::find(names.begin(), names.end(), name) != names.end();
}

std::string builtin_chamber_json(const std::string& name) {
  if (name == "thermal") return thermal_profile().dump(1);
  if (name == "thermal-short") return thermal_short_profile().dump(1);
  throw std::invalid_argument("unknown built-in chamber profile '" + name + "'");
}

ChamberProfile load_chamber_profile(const std::string& name_or_path) {
  if (is_builtin_chamber(name_or_path)) return compile_chamber_profile(builtin_chamber_json(name_or_path));
  std::ifstream in(name_or_path);
  if (!in) throw std::invalid_argument("chamber profile '" + name_or_path + "': neither a built-in nor a readable file");
  std::stringstream ss;
  ss << in.rdbuf();
  return compile_chamber_profile(ss.str());
}

double first_order_lag_step(double y0, double u0, double u1, double h, double tau) {
  if (tau <= 0) return u1;
  const double slope = (u1 - u0) / h;
  const double e = std::exp(-h / tau);
  // y(t) = u(t) - tau*slope + (y0 - u0 + tau*slope) e^{-t/tau}: exact for a linear input.
  return u1 - tau * slope + (y0 - u0 + tau * slope) * e;
}

// ---------------------------------------------------------------------------------------------
int CoverageMap::T_bins() const { return std::max(1, static_cast<int>(std::lround((T_hi_C - T_lo_C) / T_bin_C))); }
int CoverageMap::rate_bins() const {
  return std::max(1, static_cast<int>(std::lround((rate_hi_C_per_min - rate_lo_C_per_min) / rate_bin_C_per_min)));
}

void CoverageMap::add(double T, double rate, double s) {
  if (seconds.empty()) seconds.assign(static_cast<std::size_t>(T_bins() * rate_bins()), 0.0);
  const bool first = total_s == 0;
  total_s += s;
  T_min_C = first ? T : std::min(T_min_C, T);
  T_max_C = first ? T : std::max(T_max_C, T);
  rate_min_C_per_min = first ? rate : std::min(rate_min_C_per_min, rate);
  rate_max_C_per_min = first ? rate : std::max(rate_max_C_per_min, rate);
  const int i = static_cast<int>(std::floor((T - T_lo_C) / T_bin_C));
  const int k = static_cast<int>(std::floor((rate - rate_lo_C_per_min) / rate_bin_C_per_min));
  if (i < 0 || i >= T_bins() || k < 0 || k >= rate_bins()) return;
  seconds[static_cast<std::size_t>(i * rate_bins() + k)] += s;
}

namespace {
// Share of T bins with at least min_s seconds in rate bins selected by `use`.
template <class Pred>
double T_fraction(const CoverageMap& m, double min_s, Pred use) {
  if (m.seconds.empty()) return 0.0;
  int hit = 0;
  for (int i = 0; i < m.T_bins(); ++i) {
    double s = 0;
    for (int k = 0; k < m.rate_bins(); ++k) {
      const double centre = m.rate_lo_C_per_min + (k + 0.5) * m.rate_bin_C_per_min;
      if (use(centre)) s += m.seconds[static_cast<std::size_t>(i * m.rate_bins() + k)];
    }
    hit += s >= min_s;
  }
  return static_cast<double>(hit) / m.T_bins();
}
}  // namespace

double CoverageMap::heating_T_fraction(double min_s) const {
  return T_fraction(*this, min_s, [&](double r) { return r > rate_bin_C_per_min; });
}
double CoverageMap::cooling_T_fraction(double min_s) const {
  return T_fraction(*this, min_s, [&](double r) { return r < -rate_bin_C_per_min; });
}
double CoverageMap::rest_T_fraction(double min_s) const {
  return T_fraction(*this, min_s, [&](double r) { return std::abs(r) <= rate_bin_C_per_min; });
}

std::string CoverageMap::ascii() const {
  std::string out;
  char buf[64];
  std::snprintf(buf, sizeof buf, "dT/dt %+.2f .. %+.2f C/min ->\n", rate_lo_C_per_min, rate_hi_C_per_min);
  out += buf;
  for (int i = T_bins() - 1; i >= 0; --i) {
    std::snprintf(buf, sizeof buf, "%6.1f C |", T_lo_C + (i + 0.5) * T_bin_C);
    out += buf;
    for (int k = 0; k < rate_bins(); ++k) {
      const double s = seconds.empty() ? 0.0 : seconds[static_cast<std::size_t>(i * rate_bins() + k)];
      out += s <= 0 ? ' ' : s < 60 ? '.' : s < 600 ? ':' : '#';
    }
    out += "|\n";
  }
  return out;
}

std::string CoverageMap::to_json() const {
  json j = {{"T_lo_C", T_lo_C},
            {"T_hi_C", T_hi_C},
            {"T_bin_C", T_bin_C},
            {"rate_lo_C_per_min", rate_lo_C_per_min},
            {"rate_hi_C_per_min", rate_hi_C_per_min},
            {"rate_bin_C_per_min", rate_bin_C_per_min},
            {"T_reached_C", {T_min_C, T_max_C}},
            {"rate_reached_C_per_min", {rate_min_C_per_min, rate_max_C_per_min}},
            {"heating_T_fraction", heating_T_fraction()},
            {"cooling_T_fraction", cooling_T_fraction()},
            {"rest_T_fraction", rest_T_fraction()}};
  json rows = json::array();
  for (int i = 0; i < T_bins(); ++i) {
    json row = json::array();
    for (int k = 0; k < rate_bins(); ++k)
      row.push_back(seconds.empty() ? 0.0 : seconds[static_cast<std::size_t>(i * rate_bins() + k)]);
    rows.push_back(row);
  }
  j["seconds"] = rows;
  return j.dump();
}

CoverageMap predict_coverage(const ChamberProfile& profile, const ThermalLags& lags, CoverageMap grid, double step_s) {
  grid.seconds.assign(static_cast<std::size_t>(grid.T_bins() * grid.rate_bins()), 0.0);
  grid.T_min_C = grid.T_max_C = grid.rate_min_C_per_min = grid.rate_max_C_per_min = grid.total_s = 0.0;
  // Start in equilibrium at the first set point, as a run that begins with a soak does.
  double air = profile.setpoint_C(0.0), case_C = air, sensor = air;
  const double max_step_C = lags.chamber_max_rate_C_per_min / 60.0 * step_s;
  const auto n = static_cast<long>(std::ceil(profile.duration_s() / step_s));
  for (long k = 0; k < n; ++k) {
    const double t0 = static_cast<double>(k) * step_s, t1 = t0 + step_s;
    const double sp0 = profile.setpoint_C(t0), sp1 = profile.setpoint_C(t1);
    const double air0 = air, case0 = case_C, sensor0 = sensor;
    air = std::clamp(first_order_lag_step(air0, sp0, sp1, step_s, lags.chamber_tau_s), air0 - max_step_C,
                     air0 + max_step_C);
    case_C = first_order_lag_step(case0, air0, air, step_s, lags.case_tau_s);
    sensor = first_order_lag_step(sensor0, case0, case_C, step_s, lags.sensor_tau_s);
    grid.add(0.5 * (sensor0 + sensor), (sensor - sensor0) / step_s * 60.0, step_s);
  }
  return grid;
}

}  // namespace imucal::motion
