#include "plan/plan.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <stdexcept>

#include "core/coefficients.hpp"
#include "core/units.hpp"
#include "plan/optimize.hpp"
#include "sim/simulator.hpp"
#include "estimators/nav_filter.hpp"
#include "pipeline/pipeline.hpp"

namespace imucal::plan {

using nlohmann::json;

namespace {


// A stage-3 state block as the model's coefficients: name prefix, unit scale, the axes' labels,
// and the motion that makes it observable (method.md, stage 3; docs/programs.md).
struct BlockName {
  navfilter::Block block;
  const char* prefix;
  double scale;
  std::array<const char*, 6> axes;
  const char* fix;
};

const std::vector<BlockName>& block_names() {
  using namespace navfilter::state;
  static const std::vector<BlockName> names = {
      {kGyroBias, "gyro.bias_dph", units::kRadpsToDph, {"x", "y", "z"},
       "statics in several orientations, or the slow 360 deg swings about each table axis"},
      {kAccelBias, "accel.bias_mps2", 1.0, {"x", "y", "z"}, "each axis horizontal in both directions (swings, tilts)"},
      {kGyroScalePos, "gyro.scale_pos_ppm", 1e6, {"x", "y", "z"}, "rotation at rate about the axis, positive direction"},
      {kGyroScaleNeg, "gyro.scale_neg_ppm", 1e6, {"x", "y", "z"}, "rotation at rate about the axis, negative direction"},
      {kAccelScale, "accel.scale_ppm", 1e6, {"x", "y", "z"}, "the axis turned through up and down (swings through +-g)"},
      {kGyroAngles, "gyro.misalignment_arcsec", units::kRadToArcsec, {"xy", "xz", "yx", "yz", "zx", "zy"},
       "rotation about the other two axes"},
      {kAccelAngles, "accel.misalignment_arcsec", units::kRadToArcsec, {"yz", "zx", "zy"},
       "the axis pair turned through g (swings about the third axis)"},
      {kGyroDelay, "gyro.delay_us", 1e6, {"x", "y", "z"},
       "fast oscillations about each axis, and in phase about two axes (coning) for the relative delays"},
      {kAccelDelay, "accel.delay_us", 1e6, {"x", "y", "z"}, "fast oscillations with the axis horizontal"},
      {kLeverArmY, "accel.lever_arm_mm.y", 1e3, {"x", "y", "z"}, "fast oscillations about each axis (program lever-arm)"},
      {kLeverArmZ, "accel.lever_arm_mm.z", 1e3, {"x", "y", "z"}, "fast oscillations about each axis (program lever-arm)"},
  };
  return names;
}

json state_sigma_json(const navfilter::StateVector& sigma) {
  json out = json::object();
  for (const BlockName& b : block_names())
    for (int i = 0; i < b.block.size; ++i)
      out[std::string(b.prefix) + "." + b.axes[static_cast<std::size_t>(i)]] = sigma[b.block.index + i] * b.scale;
  return out;
}

const char* stage_key(pipeline::Stage s) {
  switch (s) {
    case pipeline::Stage::Direct: return "direct";
    case pipeline::Stage::LeverArm: return "lever-arm";
    case pipeline::Stage::Tumble: return "tumble";
    case pipeline::Stage::Navigation: return "navigation";
    default: return "other";
  }
}

// Every number of a model's sigma section replaced by the RMS over `models` (leaf by leaf).
void rms_sigma(json& acc, const json& add, int n_added) {
  if (acc.is_number() && add.is_number()) {
    const double a = acc.get<double>(), b = add.get<double>();
    acc = std::sqrt((a * a * (n_added - 1) + b * b) / n_added);
  } else if (acc.is_object() && add.is_object()) {
    for (auto& [k, v] : acc.items())
      if (add.contains(k)) rms_sigma(v, add.at(k), n_added);
  } else if (acc.is_array() && add.is_array() && acc.size() == add.size()) {
    for (std::size_t i = 0; i < acc.size(); ++i) rms_sigma(acc[i], add[i], n_added);
  }
}

std::vector<ImuFrame> simulate(const motion::Program& program, const ImuModel& imu, const Options& options,
                               std::uint64_t seed, RecordingMeta& meta, std::vector<TempSample>& temps) {
  sim::SimConfig cfg;
  cfg.rate_hz = options.rate_hz;
  cfg.seed = seed;
  cfg.site = options.site;
  cfg.table = options.table;
  sim::Simulator sim(program, imu, cfg);
  meta = sim.meta();
  std::vector<ImuFrame> frames;
  frames.reserve(static_cast<std::size_t>(sim.frame_count()));
  ImuFrame f;
  while (sim.next(f)) frames.push_back(f);
  temps = sim.take_temps();
  return frames;
}

// The seed's bias figures (method.md, stage 3; optimize.hpp seed_targets): what a nonlinear
// term's uncertainty at 1 g is measured against.
Targets seed_bias_targets() {
  const Targets seed = seed_targets();
  return {{"gyro.bias_dph", seed.at("gyro.bias_dph")}, {"accel.bias_mps2", seed.at("accel.bias_mps2")}};
}

bool has_noise(const ImuModel& m) {
  return m.gyro.noise.arw_rad_rts > 0 || m.accel.noise.vrw_mps_rts > 0;
}

}  // namespace

json stage3_states_json() {
  json out = json::object();
  for (const BlockName& b : block_names())
    for (int i = 0; i < b.block.size; ++i)
      out[std::string(b.prefix) + "." + b.axes[static_cast<std::size_t>(i)]] = json::array({b.block.name, i});
  return out;
}

std::vector<Weak> nonlinear_shortfall(const ImuModel& tumble_model, const Targets& bias) {
  // A term's sigma at 1 g is a bias error of that size wherever the unit meets 1 g (CONVENTIONS.md,
  // "Nonlinear terms": K2 f^2/g, K3 f^3/g^2, G f/g): ug -> m/s^2, deg/h/g -> deg/h.
  struct Term {
    const char* prefix;
    const char* bias_group;
    double to_bias;  // the term's sigma times this is the bias error at 1 g, in the bias's unit
    const char* unit;
    const char* bias_unit;
  };
  const Term terms[] = {
      {"accel.k2_ug_per_g2.", "accel.bias_mps2", 1e-6 * units::kStandardGravity_mps2, "ug/g^2", "m/s^2"},
      {"accel.k3_ug_per_g3.", "accel.bias_mps2", 1e-6 * units::kStandardGravity_mps2, "ug/g^3", "m/s^2"},
      {"gyro.g_sensitivity_dph_per_g.", "gyro.bias_dph", 1.0, "deg/h/g", "deg/h"}};
  std::vector<Weak> out;
  for (const Coefficient& c : model_coefficients(tumble_model))
    for (const Term& t : terms) {
      const auto target = bias.find(t.bias_group);
      if (c.key.rfind(t.prefix, 0) != 0 || target == bias.end() || !(c.sigma > 0)) continue;
      const double at_1g = c.sigma * t.to_bias;
      if (at_1g <= target->second) continue;
      char why[200];
      std::snprintf(why, sizeof why, "sigma %.3g %s: at 1 g a bias error of %.3g %s, %.1fx the seed's %.3g", c.sigma,
                    t.unit, at_1g, t.bias_unit, at_1g / target->second, target->second);
      // White noise over the statics: the sigma falls as one over the root of their total time.
      const double ratio = at_1g / target->second;
      char fix[200];
      std::snprintf(fix, sizeof fix,
                    "%.1fx the static time (the sigma falls as its root; 'tumble' has 24 statics of 36 s, "
                    "'tumble-short' 12 of 20 s)",
                    ratio * ratio);
      out.push_back({"tumble", c.key, why, fix});
    }
  return out;
}

namespace {

// The budget of a stage's predicted model by coefficient, and for each bench source (`bench`: its
// 1-sigma by name) the largest 1-sigma at which every coefficient meets `limits`.
void bench_requirements(StagePrediction& sp, const ImuModel& model, const std::map<std::string, double>& bench,
                        const Targets& limits) {
  sp.budget = coefficient_budgets(model);
  sp.limits = limits;
  std::vector<std::string> sources, table_sources, site_sources;
  for (const auto& entry : bench) {
    sources.push_back(entry.first);
    (entry.first.rfind("table.", 0) == 0 ? table_sources : site_sources).push_back(entry.first);
  }
  for (const std::string& s : sources) {
    std::vector<std::string> others = sources;
    std::erase(others, s);
    sp.requirements.push_back(
        {s, bench.at(s), source_requirement(sp.budget, limits, {s}, others), source_requirement(sp.budget, limits, {s})});
  }
  if (!table_sources.empty()) sp.whole_table = source_requirement(sp.budget, limits, table_sources, site_sources);
}

}  // namespace

table::TableCertificate uniform_table_certificate(double sigma_arcsec) {
  const double s = sigma_arcsec * units::kArcsecToRad;
  table::TableGeometry sigma;
  sigma.outer_tilt_rad = sigma.middle_axis_rad = sigma.inner_axis_rad = {s, s};
  for (auto& axis : sigma.encoder_error) axis = {{1, s, 0.0}, {2, s, 0.0}};
  char name[96];
  std::snprintf(name, sizeof name, "every parameter %g arcsec (1-sigma), encoder harmonics 1 and 2", sigma_arcsec);
  return {std::nullopt, sigma, name};
}

Prediction predict(const motion::Program& program, const ImuModel& imu, const Options& options) {
  if (!has_noise(imu))
    throw std::invalid_argument(
        "the IMU model has no noise: give gyro.noise.arw_deg_rth and accel.noise.vrw_mps_rth (the prediction "
        "scales with them)");
  RecordingMeta meta;
  std::vector<TempSample> temps;
  std::vector<ImuFrame> frames = simulate(program, imu, options, options.seed, meta, temps);
  const pipeline::MemorySource source(std::move(frames), std::move(temps));

  std::vector<pipeline::Stage> stages;
  for (const pipeline::Stage s : pipeline::stages_for_parts(meta))
    if (s == pipeline::Stage::Direct || s == pipeline::Stage::Tumble || s == pipeline::Stage::LeverArm ||
        s == pipeline::Stage::Navigation)
      stages.push_back(s);
  if (stages.empty())
    throw std::invalid_argument("program '" + program.name +
                                "' feeds no calibration stage (direct, tumble, lever-arm or navigation): nothing to predict");
  // Without stage 1 the later stages start from the unit's model (what stage 1 would have given).
  const bool with_direct = std::find(stages.begin(), stages.end(), pipeline::Stage::Direct) != stages.end();
  // Stage 1 from the unit's nonlinear terms, as a campaign gives it a tumble's and a rate-steps
  // test's model (stage 1 cannot determine them; without them they would read as its constants).
  ImuModel start = imu;
  if (with_direct) {
    start = ImuModel{};
    start.gyro.scale_nonlinear = imu.gyro.scale_nonlinear;
    start.gyro.g_sensitivity_radps_per_g = imu.gyro.g_sensitivity_radps_per_g;
    start.accel.k2_per_g = imu.accel.k2_per_g;
    start.accel.k3_per_g2 = imu.accel.k3_per_g2;
  }

  Prediction p;
  p.program = program.name;
  p.duration_s = program.duration_s();
  p.rate_hz = options.rate_hz;
  // Progress: each simulated run an equal share, read through ProgressSource.
  const int extra_runs = std::any_of(stages.begin(), stages.end(), [](pipeline::Stage s) { return s != pipeline::Stage::Navigation; })
                             ? std::max(0, options.residual_stage_runs - 1)
                             : 0;
  const double share = 1.0 / (1 + extra_runs);
  const auto report = [&options](double f) {
    if (options.progress) options.progress(f);
  };
  const double end_s = pipeline::end_of_program_s(meta);
  std::vector<pipeline::Outcome> outcomes = pipeline::run_to_end(
      meta, pipeline::ProgressSource(source, end_s, report, 0.0, share), stages, false, start, options.settings);
  // The stages whose sigma comes from residuals, again on other seeds: their RMS sigma, and the
  // RMS of each entry of the budget behind it.
  std::vector<pipeline::Stage> residual_stages;
  for (const pipeline::Stage s : stages)
    if (s != pipeline::Stage::Navigation) residual_stages.push_back(s);
  const auto uncertainty = [](const ImuModel& m) {
    const json j = json::parse(imu_model_to_json_text(m));
    return j.contains("sigma") ? json{{"sigma", j.at("sigma")}, {"budget", j.value("budget", json::object())}} : json();
  };
  std::vector<json> sigma_rms(outcomes.size());
  for (std::size_t i = 0; i < outcomes.size(); ++i)
    if (outcomes[i].model) sigma_rms[i] = uncertainty(*outcomes[i].model);
  for (int run = 1; run < options.residual_stage_runs && !residual_stages.empty(); ++run) {
    RecordingMeta m;
    std::vector<TempSample> t;
    std::vector<ImuFrame> f = simulate(program, imu, options, options.seed + static_cast<std::uint64_t>(run), m, t);
    const pipeline::MemorySource again(std::move(f), std::move(t));
    const pipeline::ProgressSource reported(again, end_s, report, share * run, share);
    for (const pipeline::Outcome& o : pipeline::run_to_end(m, reported, residual_stages, false, start, options.settings))
      for (std::size_t i = 0; i < outcomes.size(); ++i)
        if (outcomes[i].stage == o.stage && o.model && !sigma_rms[i].is_null())
          rms_sigma(sigma_rms[i], uncertainty(*o.model), run + 1);
  }
  for (std::size_t i = 0; i < outcomes.size(); ++i)
    if (outcomes[i].model && outcomes[i].stage != pipeline::Stage::Navigation && !sigma_rms[i].is_null()) {
      json m = json::parse(imu_model_to_json_text(*outcomes[i].model));
      m["sigma"] = sigma_rms[i].at("sigma");
      if (!sigma_rms[i].at("budget").empty()) m["budget"] = sigma_rms[i].at("budget");
      outcomes[i].model = imu_model_from_json_text(m.dump(), "the predicted model");
    }
  for (const pipeline::Outcome& o : outcomes) {
    StagePrediction sp;
    sp.stage = stage_key(o.stage);
    sp.status = pipeline::to_string(o.status);
    sp.message = o.message;
    sp.model = o.model;
    // Stage 1 and stage 3 state a budget of the bench's sources (stage 3 as its filter's consider
    // parameters, the same list): its dominant sources, and what the bench must give for the
    // stage's limits.
    if (o.stage == pipeline::Stage::Direct && o.model)
      bench_requirements(sp, *o.model, direct::bench_source_sigmas(meta, options.settings.direct), stage1_limits());
    if (o.stage == pipeline::Stage::Navigation && o.model) {
      direct::Options as_stage3;  // the bench's sigmas as stage 3 was told them
      as_stage3.gravity_sigma_mps2 = options.settings.navigation.gravity_sigma_mps2;
      bench_requirements(sp, *o.model, direct::bench_source_sigmas(meta, as_stage3), stage3_limits());
    }
    if (o.status == pipeline::Status::Undetermined || o.status == pipeline::Status::Failed) {
      // The stage's message lists what it cannot determine, one "  - what: why (fix)" per line.
      bool listed = false;
      std::size_t at = 0;
      while ((at = o.message.find("\n  - ", at)) != std::string::npos) {
        at += 5;
        const std::string line = o.message.substr(at, o.message.find('\n', at) - at);
        const std::size_t colon = line.find(": "), open = line.rfind(" (");
        Weak w{sp.stage, line.substr(0, colon), line, "see why"};
        const bool has_fix = colon != std::string::npos && open != std::string::npos && open > colon && line.back() == ')';
        if (colon != std::string::npos)
          w.why = line.substr(colon + 2, has_fix ? open - colon - 2 : std::string::npos);
        if (has_fix) w.fix = line.substr(open + 2, line.size() - open - 3);
        p.weak.push_back(std::move(w));
        listed = true;
      }
      if (!listed) p.weak.push_back({sp.stage, "(the stage)", o.message, "see why: it names the motion that is missing"});
    }
    if (o.stage == pipeline::Stage::Tumble && o.model) {
      const std::vector<Weak> shortfall = nonlinear_shortfall(*o.model, seed_bias_targets());
      p.short_of_needs.insert(p.short_of_needs.end(), shortfall.begin(), shortfall.end());
    }
    if (const auto* navigation = o.result_as<navfilter::Result>()) {
      const navfilter::Result& r = *navigation;
      json t = json::array(), sig = json::object();
      for (const navfilter::HistoryRecord& h : r.history) {
        t.push_back(h.t_s);
        const json row = state_sigma_json(h.sigma);  // named: items() of a temporary would dangle
        for (const auto& [name, v] : row.items()) sig[name].push_back(v);
      }
      sp.history = {{"t_s", t}, {"sigma", sig}};
      for (const BlockName& b : block_names())
        for (int i = 0; i < b.block.size; ++i) {
          const int k = b.block.index + i;
          const double reduction = r.sigma_final[k] > 0 ? r.sigma0[k] / r.sigma_final[k] : 0.0;
          if (reduction >= options.weak_reduction) continue;
          char why[160];
          std::snprintf(why, sizeof why, "sigma only %.2fx smaller than at the start (%.3g -> %.3g)", reduction,
                        r.sigma0[k] * b.scale, r.sigma_final[k] * b.scale);
          p.weak.push_back({sp.stage, std::string(b.prefix) + "." + b.axes[static_cast<std::size_t>(i)], why, b.fix});
        }
    }
    p.stages.push_back(std::move(sp));
  }
  // The nonlinear terms (CONVENTIONS.md, "Nonlinear terms"): the stages predicted here do not
  // estimate them; stage 1 and stage 3 take them from the model. Named, with the program that
  // determines each, unless this program runs it too.
  const std::vector<pipeline::Stage> all = pipeline::stages_for_parts(meta);
  const auto runs = [&](pipeline::Stage s) { return std::find(all.begin(), all.end(), s) != all.end(); };
  struct Term {
    const char* coefficient;
    bool in_model;
    pipeline::Stage by;
    const char* fix;
  };
  const Term terms[] = {
      {"gyro.scale_nonlinear_ppm", !imu.gyro.scale_nonlinear.isZero(0.0), pipeline::Stage::RateSteps,
       // A cubic term needs the full ladder: over twenty noise seeds its eleven rates find a 0.2 ppm
       // c3 every time, the short ladder's eight 19 times with a term invented once
       // (RateStepsLong.ACubicOfPointTwoPpmOverTwentySeeds).
       imu.gyro.scale_nonlinear.col(2).isZero(0.0)
           ? "run 'rate-steps' (or 'rate-steps-short') and give its model to the calibration"
           : "run 'rate-steps' (not 'rate-steps-short': a cubic term needs its eleven rates) and give its model "
             "to the calibration"},
      {"gyro.g_sensitivity_dph_per_g", !imu.gyro.g_sensitivity_radps_per_g.isZero(0.0), pipeline::Stage::Tumble,
       "run 'tumble' (or 'tumble-short') and give its model to the calibration"},
      {"accel.k2_ug_per_g2", !imu.accel.k2_per_g.isZero(0.0), pipeline::Stage::Tumble,
       "run 'tumble' (or 'tumble-short') and give its model to the calibration"},
      {"accel.k3_ug_per_g3", !imu.accel.k3_per_g2.isZero(0.0), pipeline::Stage::Tumble,
       "run 'tumble' (or 'tumble-short') and give its model to the calibration"}};
  for (const Term& t : terms) {
    if (runs(t.by)) continue;
    p.from_model.push_back({stage_key(stages.front()), t.coefficient,
                      t.in_model ? "not determined by this program: stage 1 and stage 3 take it from the model given"
                                 : "not determined by this program and not in the model given: taken as zero (an IMU "
                                   "with it shows it in stage 1's constants)",
                      t.fix});
  }
  report(1.0);
  return p;
}

json Prediction::to_json() const {
  json st = json::object();
  for (const StagePrediction& s : stages) {
    json e = {{"status", s.status}};
    if (!s.message.empty()) e["message"] = s.message;
    if (s.model) {
      const json m = json::parse(imu_model_to_json_text(*s.model));
      e["frame"] = m.value("frame", "instrument");
      e["sigma"] = m.value("sigma", json::object());
      e["estimates"] = pipeline::estimates_json(*s.model);
    }
    if (!s.history.is_null()) e["history"] = s.history;
    if (!s.budget.empty()) {
      json b = json::object();
      for (const CoefficientBudget& c : s.budget)
        b[c.key] = {{"combined", c.combined}, {"dominant", c.dominant}, {"contributions", c.contributions}};
      e["budget"] = b;
    }
    if (!s.limits.empty()) {
      // What the bench must give for the stage's limits (combined standard uncertainty <= limit).
      // A factor on a 1-sigma; with the sigma, the largest 1-sigma itself (null: unbounded).
      const auto bound = [](const SourceRequirement& r, double sigma) {
        const bool bounded = std::isfinite(r.max_factor);
        json out = {{"max_factor", bounded ? json(r.max_factor) : json(nullptr)},
                    {"limiting", bounded ? json(r.limiting) : json(nullptr)}};
        if (sigma > 0) out["max_sigma"] = bounded ? json(sigma * r.max_factor) : json(nullptr);
        return out;
      };
      json sources = json::array();
      for (const StagePrediction::Requirement& r : s.requirements)
        sources.push_back({{"source", r.source}, {"sigma", r.sigma}, {"alone", bound(r.alone, r.sigma)},
                           {"with_others", bound(r.with_others, r.sigma)}});
      e["requirements"] = {{"limits", s.limits}, {"sources", sources},
                           {"whole_table", s.whole_table ? bound(*s.whole_table, 0.0) : json(nullptr)}};
    }
    st[s.stage] = e;
  }
  const auto list = [](const std::vector<Weak>& v) {
    json w = json::array();
    for (const Weak& x : v) w.push_back({{"stage", x.stage}, {"coefficient", x.coefficient}, {"why", x.why}, {"fix", x.fix}});
    return w;
  };
  return {{"format", "imucal-plan/1"}, {"program", program}, {"duration_s", duration_s}, {"rate_hz", rate_hz},
          {"stages", st}, {"weak", list(weak)}, {"from_model", list(from_model)},
          {"short_of_needs", list(short_of_needs)}};
}

}  // namespace imucal::plan
