#include "plan/optimize.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>
#include <set>
#include <stdexcept>

#include "pipeline/pipeline.hpp"

namespace imucal::plan {

using nlohmann::json;

Targets seed_targets() {
  return {{"gyro.bias_dph", 0.001},          {"gyro.scale_pos_ppm", 0.5}, {"gyro.scale_neg_ppm", 0.5},
          {"gyro.misalignment_arcsec", 0.1}, {"gyro.delay_us", 1.0},      {"accel.bias_mps2", 5e-6},
          {"accel.scale_ppm", 0.3},          {"accel.misalignment_arcsec", 0.3}};
}

namespace {

// "gyro.bias_dph" of "gyro.bias_dph.x": what a target names.
std::string group_of(const std::string& name) { return name.substr(0, name.rfind('.')); }

// The groups a target may name: those of the keys a model's estimates carry
// (pipeline::estimates_json), every optional one included.
std::set<std::string> target_groups() {
  ImuErrorSet every;
  const Eigen::Vector3d one = Eigen::Vector3d::Ones();
  every.gyro.delay_s = every.accel.delay_s = every.accel.lever_arm_y_m = every.accel.lever_arm_z_m = one;
  every.accel.k2_per_g = every.accel.k3_per_g2 = one;
  every.gyro.scale_nonlinear.setOnes();
  every.gyro.g_sensitivity_radps_per_g.setOnes();
  ImuModel model;
  model.sigma = every;
  std::set<std::string> groups;
  const json estimates = pipeline::estimates_json(model);  // named: items() of a temporary dangles
  for (const auto& [name, value] : estimates.items()) groups.insert(group_of(name));
  return groups;
}

}  // namespace

Targets targets_from_json(const json& j) {
  if (!j.is_object() || j.empty())
    throw std::invalid_argument("targets must be an object of coefficient groups and 1-sigma values, e.g. "
                                "{\"gyro.bias_dph\": 0.001}");
  // A misspelt group would match no coefficient and read as "no program meets it".
  static const std::set<std::string> groups = target_groups();
  Targets t;
  for (const auto& [group, v] : j.items()) {
    if (groups.count(group) == 0) {
      std::string known;
      for (const std::string& g : groups) known += (known.empty() ? "" : ", ") + g;
      throw std::invalid_argument("target '" + group + "' is not a coefficient group (the groups: " + known + ")");
    }
    if (!v.is_number() || !(v.get<double>() > 0))
      throw std::invalid_argument("target '" + group + "' must be a positive number (a 1-sigma in the key's unit)");
    t[group] = v.get<double>();
  }
  return t;
}

std::string scaled_program(const json& program, double swing_period_factor, double oscillation_factor,
                           double slow_period_s) {
  json p = program;
  for (json& s : p.at("segments")) {
    if (s.value("type", "") != "sine" && s.value("type", "") != "coning") continue;
    const double period = s.value("period_s", 0.0);
    if (period >= slow_period_s) {
      s["period_s"] = period * swing_period_factor;
    } else if (s.contains("cycles")) {
      // At least two cycles: an oscillation is seen as one only over a few periods.
      s["cycles"] = std::max(2, static_cast<int>(std::lround(s.at("cycles").get<double>() * oscillation_factor)));
    }
  }
  p["name"] = p.value("name", std::string("program")) + "-optimized";
  p["comment"] = "imucal plan --optimize: slow swing periods x" + std::to_string(swing_period_factor) +
                 ", fast oscillation cycles x" + std::to_string(oscillation_factor) + " of " +
                 program.value("name", std::string("the program"));
  return p.dump(1);
}

namespace {

// Each coefficient's predicted sigma after the last stage that determines it (stage 3 refines
// stage 1), as the builder shows it (web/js/plan.mjs).
std::map<std::string, double> final_sigmas(const Prediction& p) {
  std::map<std::string, double> out;
  for (const char* stage : {"direct", "lever-arm", "navigation"})
    for (const StagePrediction& s : p.stages) {
      if (s.stage != stage || !s.model) continue;
      const json estimates = pipeline::estimates_json(*s.model);  // named: items() of a temporary dangles
      for (const auto& [name, pair] : estimates.items()) {
        if (!pair.is_array() || pair.size() < 2 || !pair[1].is_number()) continue;  // no sigma: not determined
        const double sigma = pair[1].get<double>();
        if (sigma > 0) out[name] = sigma;
      }
    }
  return out;
}

// Fills the candidate's duration and ratios; false when the table's limits refuse the program.
bool judge(Candidate& c, const ImuModel& imu, const Targets& targets, const motion::TableLimits& limits,
           const Options& predict_options) {
  motion::Program program;
  try {
    program = motion::compile_program(c.program_json, limits);
  } catch (const std::invalid_argument&) {
    return false;
  }
  if (!motion::validate_program(program, limits).empty()) return false;
  c.duration_s = program.duration_s();
  const std::map<std::string, double> sigma = final_sigmas(predict(program, imu, predict_options));
  c.worst_ratio = 0.0;
  c.ratio_by_group.clear();
  for (const auto& [group, target] : targets) c.ratio_by_group[group] = std::numeric_limits<double>::infinity();
  for (const auto& [group, target] : targets) {
    double worst = -1.0;
    std::string worst_name;
    for (const auto& [name, s] : sigma)
      if (group_of(name) == group && s / target > worst) {
        worst = s / target;
        worst_name = name;
      }
    if (worst < 0) {  // the program does not determine the group at all
      worst_name = group;
      worst = std::numeric_limits<double>::infinity();
    }
    c.ratio_by_group[group] = worst;
    if (worst > c.worst_ratio) {
      c.worst_ratio = worst;
      c.worst_coefficient = worst_name;
    }
  }
  return true;
}

}  // namespace

OptimizeResult optimize(const json& program, const ImuModel& imu, const Targets& targets,
                        const motion::TableLimits& limits, const OptimizeOptions& options) {
  if (!program.is_object() || !program.contains("segments"))
    throw std::invalid_argument("the program to optimize must be a program object with segments");
  if (targets.empty()) throw std::invalid_argument("no targets to meet");
  const auto t0 = std::chrono::steady_clock::now();
  const auto elapsed_s = [&] { return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count(); };
  OptimizeResult result;
  std::vector<Candidate> evaluated;
  // Judges (swing, oscillation) once; nothing when the limits refuse it or the budget is spent.
  const auto evaluate = [&](double swing, double osc) -> std::optional<Candidate> {
    for (const Candidate& c : evaluated)
      if (std::abs(c.swing_period_factor - swing) < 1e-9 && std::abs(c.oscillation_factor - osc) < 1e-9) return c;
    if (!evaluated.empty() && elapsed_s() > options.budget_s) return std::nullopt;
    Candidate c;
    c.swing_period_factor = swing;
    c.oscillation_factor = osc;
    c.program_json = scaled_program(program, swing, osc, options.slow_period_s);
    if (!judge(c, imu, targets, limits, options.predict)) return std::nullopt;
    evaluated.push_back(c);
    ++result.evaluated;
    if (options.progress) options.progress(c, result.evaluated);
    return c;
  };

  const std::optional<Candidate> reference = evaluate(1.0, 1.0);
  if (!reference) throw std::invalid_argument("the program breaks the table's limits: validate it first");
  result.reference = *reference;
  // 1. Both knobs together, shorter and shorter until a target is missed.
  double swing = 1.0, osc = 1.0;
  if (reference->worst_ratio <= 1.0) {
    for (const double s : {0.7, 0.5, 0.35, 0.25, 0.18, 0.12, 0.08}) {
      const auto c = evaluate(s, s);
      if (!c || c->worst_ratio > 1.0) break;
      swing = osc = s;
    }
    // 2. Each knob alone from there, in steps of 0.75, while every target holds.
    for (bool improved = true; improved && elapsed_s() < options.budget_s;) {
      improved = false;
      if (const auto c = evaluate(swing * 0.75, osc); c && c->worst_ratio <= 1.0) {
        swing *= 0.75;
        improved = true;
      }
      if (const auto c = evaluate(swing, osc * 0.75); c && c->worst_ratio <= 1.0) {
        osc *= 0.75;
        improved = true;
      }
    }
  } else {
    // The program as given misses a target: longer swings and more oscillations, to see whether
    // any program of its family meets them.
    for (const double s : {1.5, 2.0, 3.0}) {
      const auto c = evaluate(s, s);
      if (!c || c->worst_ratio <= 1.0) break;
    }
  }

  for (const Candidate& c : evaluated) {
    if (c.worst_ratio <= 1.0 && (!result.best || c.duration_s < result.best->duration_s)) result.best = c;
  }
  result.closest = *std::min_element(evaluated.begin(), evaluated.end(), [](const Candidate& a, const Candidate& b) {
    return a.worst_ratio < b.worst_ratio;
  });
  std::vector<Candidate> by_duration = evaluated;
  std::sort(by_duration.begin(), by_duration.end(),
            [](const Candidate& a, const Candidate& b) { return a.duration_s < b.duration_s; });
  double best_so_far = std::numeric_limits<double>::infinity();
  for (const Candidate& c : by_duration)
    if (c.worst_ratio < best_so_far) {
      result.front.push_back(c);
      best_so_far = c.worst_ratio;
    }
  for (const auto& [group, target] : targets) {
    double lowest = std::numeric_limits<double>::infinity();
    for (const Candidate& c : evaluated) lowest = std::min(lowest, c.ratio_by_group.at(group));
    if (lowest <= 1.0) continue;
    char why[200];
    if (std::isinf(lowest))
      std::snprintf(why, sizeof why, "%s: no program tried determines it (the program lacks the motion for it)",
                    group.c_str());
    else
      std::snprintf(why, sizeof why, "%s: at best %.2fx its target %g in the programs tried (longest %.0f s)",
                    group.c_str(), lowest, target, by_duration.back().duration_s);
    result.unmet.push_back(why);
  }
  result.wall_s = elapsed_s();
  return result;
}

}  // namespace imucal::plan
