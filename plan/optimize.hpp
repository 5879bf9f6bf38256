// A shorter program that delivers as much (issue 16, `imucal plan --optimize`): a search over a
// program's timing within the table's limits, each candidate judged by its prediction (plan.hpp).
//
// The family searched is the given program's own shape with two knobs, the ones that set its
// length: the period of its slow swings (sine segments of at least `slow_period_s`: the slow
// 360 deg swings that separate biases, scale factors and axis angles) and the number of cycles of
// its fast oscillations (the rest: delays and proof-mass offsets). Holds, moves and the order of
// the parts are kept (a hold of 25 s or more restarts stage 3's navigation). Each candidate is
// validated against the table's limits before it is predicted; one that breaks them is skipped.
#pragma once

#include <functional>
#include <map>
#include <optional>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "core/imu_model.hpp"
#include "motion_programs/program.hpp"
#include "plan/plan.hpp"

namespace imucal::plan {

// 1-sigma targets by coefficient group (plan::Targets, budget.hpp).
// The seed's stage-3 figures (method.md): gyro bias 0.001 deg/h, scale 0.5 ppm, angles 0.1",
// delays 1 us; accelerometer bias 5e-6 m/s^2, scale 0.3 ppm, angles 0.3".
Targets seed_targets();
// From JSON {"gyro.bias_dph": 0.001, ...}; throws std::invalid_argument naming a bad entry.
Targets targets_from_json(const nlohmann::json& j);

struct Candidate {
  double swing_period_factor = 1.0;  // times the program's slow swing periods
  double oscillation_factor = 1.0;   // times the program's fast oscillation cycles
  std::string program_json;
  double duration_s = 0.0;
  // The largest predicted sigma / target over the targets (<= 1: every target met), and which.
  double worst_ratio = 0.0;
  std::string worst_coefficient;
  std::map<std::string, double> ratio_by_group;  // worst ratio within each target group
};

struct OptimizeOptions {
  Options predict;              // rate (default 20 Hz here: the search predicts many programs)
  double budget_s = 300.0;      // wall time for the search
  double slow_period_s = 100.0;
  std::function<void(const Candidate&, int evaluated)> progress;  // after each prediction
};

struct OptimizeResult {
  Candidate reference;                 // the program as given
  std::optional<Candidate> best;       // the shortest that meets every target
  Candidate closest;                   // when none does: the best worst ratio
  std::vector<Candidate> front;        // duration against worst ratio, non-dominated, shortest first
  std::vector<std::string> unmet;      // targets no candidate met, each with why
  int evaluated = 0;
  double wall_s = 0.0;
};

// The program with its slow swings' periods and fast oscillations' cycles scaled (JSON text).
std::string scaled_program(const nlohmann::json& program, double swing_period_factor, double oscillation_factor,
                           double slow_period_s);

OptimizeResult optimize(const nlohmann::json& program, const ImuModel& imu, const Targets& targets,
                        const motion::TableLimits& limits, const OptimizeOptions& options = {});

}  // namespace imucal::plan
