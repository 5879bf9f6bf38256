// imucal plan: the predicted 1-sigma of every coefficient before the table moves, and the program
// search.
#include "cli/commands.hpp"

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <fstream>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "core/imu_model.hpp"
#include "motion_programs/program.hpp"
#include "plan/optimize.hpp"
#include "plan/plan.hpp"

namespace imucal::cli {

// `imucal plan`: the predicted 1-sigma of every coefficient after each stage the program feeds.
int run_plan(const std::string& program_arg, const std::string& imu_path, const plan::Options& opt,
             const std::string& json_out) {
  const motion::Program program = motion::load_program(program_arg, motion::TableLimits{});
  const ImuModel imu = read_imu_model_file(imu_path);
  const auto t0 = std::chrono::steady_clock::now();
  const plan::Prediction p = plan::predict(program, imu, opt);
  const double wall_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  const nlohmann::json j = p.to_json();
  std::printf("program %s: %.0f s (%.1f h) at %.0f Hz; predicted 1-sigma after each stage (%.1f s to compute)\n",
              p.program.c_str(), p.duration_s, p.duration_s / 3600.0, p.rate_hz, wall_s);
  // One row per coefficient a stage predicts (a sigma above zero), a column per stage.
  std::vector<std::string> names;
  for (const auto& [stage, e] : j.at("stages").items())
    if (e.contains("estimates"))
      for (const auto& [name, v] : e.at("estimates").items())
        if (v.at(1).get<double>() > 0 && std::find(names.begin(), names.end(), name) == names.end())
          names.push_back(name);
  // Stage 1's and stage 3's budgets: each coefficient's dominant source and its share of the variance.
  std::vector<std::string> with_budget;
  for (const auto& [stage, e] : j.at("stages").items())
    if (e.contains("budget")) with_budget.push_back(stage);
  std::printf("  %-30s", "coefficient");
  for (const auto& [stage, e] : j.at("stages").items()) std::printf(" %14s", stage.c_str());
  if (!with_budget.empty()) std::printf("  %s", "dominant source (its share of u^2)");
  std::printf("\n");
  for (const std::string& name : names) {
    std::printf("  %-30s", name.c_str());
    for (const auto& [stage, e] : j.at("stages").items()) {
      if (e.contains("estimates") && e.at("estimates").contains(name)) {
        std::printf(" %14.4g", e.at("estimates").at(name).at(1).get<double>());
      } else {
        std::printf(" %14s", e.value("status", "-") == "done" ? "-" : e.value("status", "-").c_str());
      }
    }
    for (const std::string& stage : with_budget) {
      const nlohmann::json& budget = j.at("stages").at(stage).at("budget");
      if (!budget.contains(name)) continue;
      const nlohmann::json& b = budget.at(name);
      const std::string dominant = b.at("dominant").get<std::string>();
      const double x = b.at("contributions").at(dominant).get<double>(), u = b.at("combined").get<double>();
      std::printf("  %s: %s (%.0f %%)", stage.c_str(), dominant.c_str(), u > 0 ? 100.0 * x * x / (u * u) : 0.0);
    }
    std::printf("\n");
  }
  for (const auto& [stage, e] : j.at("stages").items()) {
    if (!e.contains("requirements")) continue;
    const nlohmann::json& req = e.at("requirements");
    // "at most 0.31 (gyro.bias_dph.x)", "none suffices (gyro.bias_dph.x)", "no limit"
    const auto bound = [](const nlohmann::json& b, const char* key) {
      char text[160];
      if (b.at(key).is_null())
        std::snprintf(text, sizeof text, "no limit");
      else if (b.at("max_factor").get<double>() == 0.0)
        std::snprintf(text, sizeof text, "none suffices (%s)", b.at("limiting").get<std::string>().c_str());
      else
        std::snprintf(text, sizeof text, "at most %.3g (%s)", b.at(key).get<double>(),
                      b.at("limiting").get<std::string>().c_str());
      return std::string(text);
    };
    std::printf("the bench for %s's limits (every coefficient's combined 1-sigma within its limit):\n",
                stage == "direct" ? "stage 1" : stage == "navigation" ? "stage 3" : stage.c_str());
    if (req.at("sources").empty())
      std::printf("  no bench source in the budget: give the table's certificate (--table, --table-sigma-arcsec)\n");
    else
      std::printf("  %-34s %-9s %-44s %s\n", "source", "1-sigma", "alone (no other bench error)",
                  "with the others as here");
    for (const auto& r : req.at("sources"))
      std::printf("  %-34s %-9.3g %-44s %s\n", r.at("source").get<std::string>().c_str(), r.at("sigma").get<double>(),
                  bound(r.at("alone"), "max_sigma").c_str(), bound(r.at("with_others"), "max_sigma").c_str());
    if (!req.at("whole_table").is_null())
      std::printf("  the whole table certificate scaled together (no g error): factor %s\n",
                  bound(req.at("whole_table"), "max_factor").c_str());
  }
  for (const auto& [stage, e] : j.at("stages").items())
    if (e.contains("message")) std::printf("  %s: %s\n", stage.c_str(), e.at("message").get<std::string>().c_str());
  if (!p.weak.empty()) std::printf("weakly observable or undetermined:\n");
  for (const plan::Weak& w : p.weak)
    std::printf("  %s %s: %s; needs %s\n", w.stage.c_str(), w.coefficient.c_str(), w.why.c_str(), w.fix.c_str());
  if (!p.from_model.empty()) std::printf("taken from the model (nonlinear terms this program does not determine):\n");
  for (const plan::Weak& w : p.from_model)
    std::printf("  %s: %s; to determine it, %s\n", w.coefficient.c_str(), w.why.c_str(), w.fix.c_str());
  if (!p.short_of_needs.empty()) std::printf("short of the unit's needs:\n");
  for (const plan::Weak& w : p.short_of_needs)
    std::printf("  %s %s: %s; needs %s\n", w.stage.c_str(), w.coefficient.c_str(), w.why.c_str(), w.fix.c_str());
  if (!json_out.empty()) {
    std::ofstream out(json_out);
    out << j.dump(1) << "\n";
    if (!out) throw std::runtime_error("cannot write " + json_out);
    std::printf("-> %s\n", json_out.c_str());
  }
  return 0;
}

// `imucal plan --optimize`: the shortest program of the given one's family that meets the targets.
int run_plan_optimize(const std::string& program_arg, const std::string& imu_path, const plan::OptimizeOptions& opt,
                      const std::string& target_arg, const std::string& program_out, const std::string& json_out) {
  const motion::TableLimits limits{};
  const std::string program_text = motion::load_program(program_arg, limits).source_json;
  const nlohmann::json program = nlohmann::json::parse(program_text);
  const ImuModel imu = read_imu_model_file(imu_path);
  plan::Targets targets;
  if (target_arg == "seed") {
    targets = plan::seed_targets();
  } else {
    std::ifstream in(target_arg);
    if (!in) throw std::runtime_error("cannot read the targets file " + target_arg);
    const nlohmann::json j = nlohmann::json::parse(in, nullptr, false);
    if (j.is_discarded()) throw std::runtime_error(target_arg + " is not JSON");
    targets = plan::targets_from_json(j);
  }
  std::printf("optimizing %s (%s) for %zu targets at %.0f Hz, budget %.0f s\n", program.value("name", "").c_str(),
              program_arg.c_str(), targets.size(), opt.predict.rate_hz, opt.budget_s);
  plan::OptimizeOptions o = opt;
  o.progress = [](const plan::Candidate& c, int n) {
    std::printf("  [%2d] swings x%.3f, oscillations x%.3f: %6.0f s, worst %.2f of its target (%s)\n", n,
                c.swing_period_factor, c.oscillation_factor, c.duration_s, c.worst_ratio, c.worst_coefficient.c_str());
    std::fflush(stdout);
  };
  const plan::OptimizeResult r = plan::optimize(program, imu, targets, limits, o);
  std::printf("front (duration against the worst sigma/target):\n");
  for (const plan::Candidate& c : r.front) std::printf("  %6.0f s  %.2f\n", c.duration_s, c.worst_ratio);
  for (const std::string& u : r.unmet) std::printf("unmet: %s\n", u.c_str());
  const plan::Candidate& chosen = r.best ? *r.best : r.closest;
  if (r.best)
    std::printf("best: %.0f s (%.0f %% of %.0f s), every target met, worst %.2f (%s); %d programs in %.0f s\n",
                chosen.duration_s, 100.0 * chosen.duration_s / r.reference.duration_s, r.reference.duration_s,
                chosen.worst_ratio, chosen.worst_coefficient.c_str(), r.evaluated, r.wall_s);
  else
    std::printf("no program tried meets every target; closest: %.0f s, worst %.2f (%s)\n", chosen.duration_s,
                chosen.worst_ratio, chosen.worst_coefficient.c_str());
  if (!program_out.empty()) {
    std::ofstream out(program_out);
    out << chosen.program_json << "\n";
    if (!out) throw std::runtime_error("cannot write " + program_out);
    std::printf("-> %s (accepted by simulate, campaign and the builder)\n", program_out.c_str());
  }
  if (!json_out.empty()) {
    nlohmann::json front = nlohmann::json::array();
    for (const plan::Candidate& c : r.front)
      front.push_back({{"duration_s", c.duration_s}, {"worst_ratio", c.worst_ratio}, {"worst", c.worst_coefficient},
                       {"swing_period_factor", c.swing_period_factor}, {"oscillation_factor", c.oscillation_factor}});
    const nlohmann::json j = {{"format", "imucal-plan-optimize/1"}, {"reference_duration_s", r.reference.duration_s},
                              {"met", r.best.has_value()}, {"duration_s", chosen.duration_s},
                              {"worst_ratio", chosen.worst_ratio}, {"ratio_by_group", chosen.ratio_by_group},
                              {"front", front}, {"unmet", r.unmet}, {"evaluated", r.evaluated},
                              {"program", nlohmann::json::parse(chosen.program_json)}};
    std::ofstream out(json_out);
    out << j.dump(1) << "\n";
    if (!out) throw std::runtime_error("cannot write " + json_out);
  }
  return r.best ? 0 : 2;
}

}  // namespace imucal::cli
