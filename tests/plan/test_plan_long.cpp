// The prediction agrees with reality (issue 16): for the built-in `direct` and `navigation`
// programs, 20 calibrations simulated with other seeds (the navigation-grade truth of examples/),
// each through the same pipeline as a recording: the RMS error of each coefficient lies within
// 0.7-1.4x its predicted sigma for at least 90 % of the coefficients, and the sigma the runs report
// (their RMS) lies within 20 % of the prediction. Each run's own sigma is printed too. Stage 1's
// is scaled by the white noise measured within the statics while its residuals agree with it
// (least_squares::variance_factor): on 20 runs of `direct` every run within 0.6 % of the
// prediction but the 1 % of channel-runs where the residuals' chi-square test fires by chance
// (2 of 60 gyro channel-runs here, then 7 % and 26 % off: the residuals' own variance, as for a
// unit with more than white noise); 27 of 27 coefficients with their RMS error within 0.7-1.4
// sigma. Before (the residuals' variance alone, 26-54 degrees of freedom) runs scattered by up to
// 32 %. Stage 3 starts each run from the truth with the seed's
// residual errors of stage 1 (and the proof masses off by 0.3 mm), drawn anew per run: what its
// initial covariance assumes.
//
// Stage 3's errors spread as its sigma says (issue 16), with the filter told the simulated bench:
// the table's accuracy (the strapdown floor, as NavFilterConsistency) and the simulated IMU's
// constant scale factors (no scale-factor random walk). Measured over the 20 runs (2026-11-29): 36
// of 36 coefficients with their RMS error within 0.7-1.4 sigma, from 0.71 (accel.misalignment_arcsec.zy)
// to 1.38 (accel.lever_arm_mm.y.z).
// Before: 27 of 36, the accelerometers' delays x, y, z at 1.43, 3.0 and 1.8 sigma and the
// proof-mass offsets y.z, z.y at 2.4 and 4.5 sigma (over-confident). The compensator undid the
// accelerometers' 2 ms delays (a fifth of a sample at 100 Hz) by linear interpolation of the
// cumulative output, whose error of f(1-f) dt^2 / 2 times the output's rate of change the filter's
// delay model does not have: on noise-free data it left the y delay and the offsets y.z, z.y 2.4,
// 1.9 and 4.4 sigma from the truth (now within 0.11 sigma: nav::Compensator interpolates by a
// cubic). With that fix alone 32 of 36, four conservative: the gyro z and accelerometer y scale
// factors at 0.55-0.62 from the filter's default scale-factor random walk (1e-9/sqrt(s), a real
// sensor's allowance) where the simulated scale factors are constant (docs/stage3.md), and accel
// yz at 0.63. With the filter's real-table tuning (2" of encoder attitude, which the simulated
// table does not have; EveryNavigationRunReportsThePredictedSigma, 10 runs at 50 Hz) 23 of 36,
// every miss conservative (0.25-0.67, the gyro delays at 0.3): pessimistic on this bench by design.
#include <gtest/gtest.h>

#include <cmath>
#include <algorithm>
#include <map>
#include <random>

#include "../estimators/nav_calib_fixture.hpp"
#include "core/units.hpp"
#include "pipeline/pipeline.hpp"
#include "plan/optimize.hpp"
#include "plan/plan.hpp"
#include "tests/test_paths.hpp"

using namespace imucal;
using nlohmann::json;

namespace {


ImuModel nav_grade() { return read_imu_model_file(imucaltest::source_dir() + "/examples/truth-nav-grade.json"); }


// One calibration of `program` on data simulated with `seed`: the stage's model (with its sigma).
ImuModel calibrate(const motion::Program& program, const ImuModel& truth, pipeline::Stage stage, double rate_hz,
                   std::uint64_t seed, const ImuModel& start, const pipeline::Settings& settings,
                   std::shared_ptr<const sim::MotionSignal>& signal) {
  sim::SimConfig cfg;
  cfg.rate_hz = rate_hz;
  cfg.seed = seed;
  sim::Simulator sim(program, truth, cfg);
  // The runs of one test share the motion's signal (computed by the first): each seed adds its noise.
  if (!signal) signal = sim.motion_signal();
  sim.use_motion_signal(signal);
  std::vector<ImuFrame> frames;
  ImuFrame f;
  while (sim.next(f)) frames.push_back(f);
  const auto outcomes = pipeline::run_to_end(sim.meta(), pipeline::MemorySource(std::move(frames)), {stage}, true, start, settings);
  EXPECT_EQ(outcomes.front().status, pipeline::Status::Done) << outcomes.front().message;
  return outcomes.front().model.value_or(ImuModel{});
}

// What is checked of `runs` calibrations against the prediction.
enum class Check { ErrorsAndSigmas, SigmasOnly };

void expect_prediction_holds(const std::string& program_name, pipeline::Stage stage, double rate_hz, int runs, Check check,
                             const pipeline::Settings& settings,
                             const std::function<ImuModel(std::mt19937_64&)>& start_of_run, const ImuModel& reference) {
  const ImuModel truth = nav_grade();
  const motion::Program program = motion::load_program(program_name, motion::TableLimits{});
  plan::Options opt;
  opt.rate_hz = rate_hz;
  opt.seed = 1000;
  opt.settings = settings;
  const plan::Prediction prediction = plan::predict(program, truth, opt);
  ASSERT_EQ(prediction.stages.size(), 1u);
  const std::optional<ImuModel>& predicted_model = prediction.stages[0].model;
  ASSERT_TRUE(predicted_model) << prediction.stages[0].message;
  const json predicted = pipeline::estimates_json(*predicted_model);
  ImuModel reference_named = reference;  // every coefficient the prediction names (estimates_json
  reference_named.sigma = predicted_model->sigma;  // lists those with a sigma)
  const json truth_values = pipeline::estimates_json(reference_named);
  std::map<std::string, double> sum_sq, sigma_ratio_worst, reported_sq;
  std::mt19937_64 rng(77);
  std::shared_ptr<const sim::MotionSignal> signal;
  for (int run = 0; run < runs; ++run) {
    const ImuModel m = calibrate(program, truth, stage, rate_hz, 1 + static_cast<std::uint64_t>(run), start_of_run(rng),
                                 settings, signal);
    const json got = pipeline::estimates_json(m);
    for (const auto& [name, pair] : predicted.items()) {
      const double sigma_pred = pair.at(1).get<double>();
      if (!(sigma_pred > 0) || !got.contains(name)) continue;
      const double err = got.at(name).at(0).get<double>() - truth_values.at(name).at(0).get<double>();
      sum_sq[name] += err * err;
      const double reported = got.at(name).at(1).get<double>();
      reported_sq[name] += reported * reported;
      sigma_ratio_worst[name] = std::max(sigma_ratio_worst[name], std::abs(reported / sigma_pred - 1.0));
    }
  }
  int inside = 0, every_run_within = 0, rms_within = 0;
  double worst_run = 0;
  for (const auto& [name, ss] : sum_sq) {
    const double rms = std::sqrt(ss / runs), sigma_pred = predicted.at(name).at(1).get<double>();
    const double ratio = rms / sigma_pred;
    const double reported_rms = std::sqrt(reported_sq[name] / runs);
    const bool in = ratio >= 0.7 && ratio <= 1.4;
    inside += in ? 1 : 0;
    every_run_within += sigma_ratio_worst[name] <= 0.2 ? 1 : 0;
    const bool rms_in = std::abs(reported_rms / sigma_pred - 1.0) <= 0.2;
    rms_within += rms_in ? 1 : 0;
    worst_run = std::max(worst_run, sigma_ratio_worst[name]);
    EXPECT_TRUE(rms_in) << name << ": the runs report " << reported_rms << " (RMS), predicted " << sigma_pred;
    if (check == Check::SigmasOnly) {
      EXPECT_LE(sigma_ratio_worst[name], 0.2) << name << ": a run reports a sigma more than 20 % from the prediction";
    }
    std::printf("  %-30s predicted %10.4g  rms error %10.4g  ratio %5.2f%s  reported: rms %10.4g, each within %4.1f %%\n",
                name.c_str(), sigma_pred, rms, ratio, in ? "" : "  <-- outside 0.7-1.4", reported_rms,
                100.0 * sigma_ratio_worst[name]);
  }
  const double n = static_cast<double>(sum_sq.size());
  std::printf("%s: %d of %.0f coefficients with their RMS error within 0.7-1.4 sigma; reported sigma: RMS over the "
              "runs within 20 %% for %d, every run within 20 %% for %d (worst run %.0f %%)\n",
              program_name.c_str(), inside, n, rms_within, every_run_within, 100.0 * worst_run);
  if (check == Check::ErrorsAndSigmas) {
    EXPECT_GE(inside, 0.9 * n);
  }
}

}  // namespace

TEST(PlanLong, TheDirectProgramDeliversWhatWasPredicted) {
  const ImuModel truth = nav_grade();
  // The stage (and so the prediction) told the simulated bench: its g is exact (the simulator's
  // own normal gravity, which the budget would otherwise give a gravity anomaly's 30 ppm of
  // accelerometer scale), as the navigation tests below tell the filter the simulator's table.
  pipeline::Settings simulated_bench;
  simulated_bench.direct.gravity_sigma_mps2 = 0.0;
  expect_prediction_holds("direct", pipeline::Stage::Direct, 100.0, 20, Check::ErrorsAndSigmas, simulated_bench,
                          [](std::mt19937_64&) { return ImuModel{}; }, truth);
}

namespace {

// Stage 3 from the truth with the seed's residual errors, drawn anew per run.
ImuModel navigation_start(const ImuModel& truth_body, std::mt19937_64& rng) {
  ImuModel start = truth_body;
  navcaltest::add_seed_residuals(start, rng);
  std::normal_distribution<double> n01;
  for (int j = 0; j < 3; ++j) {
    start.accel.lever_arm_y_m[j] += 0.3e-3 * n01(rng);
    start.accel.lever_arm_z_m[j] += 0.3e-3 * n01(rng);
  }
  start.sigma.reset();
  return start;
}

}  // namespace

TEST(PlanLong, EveryNavigationRunReportsThePredictedSigma) {
  const ImuModel truth_body = direct::to_body_frame(nav_grade());
  expect_prediction_holds("navigation", pipeline::Stage::Navigation, 50.0, 10, Check::SigmasOnly, {},
                          [&](std::mt19937_64& rng) { return navigation_start(truth_body, rng); }, truth_body);
}

// The errors' spread, with the filter (and so the prediction) told the bench the simulator gives:
// an exact table reference, whose noise is the strapdown algorithm's floor (as in
// NavFilterConsistency, docs/stage3.md "Honest sigmas"), and an IMU whose scale factors are
// constant (the truth has no scale-factor drift: no random walk for them in the filter either).
// `imucal plan --table-...` takes a real table's accuracy the same way.
TEST(PlanLong, TheNavigationErrorsSpreadAsPredicted) {
  const ImuModel truth_body = direct::to_body_frame(nav_grade());
  pipeline::Settings simulated_bench;
  simulated_bench.navigation.velocity_noise_mps = 1e-5;
  simulated_bench.navigation.position_noise_m = 1e-4;
  simulated_bench.navigation.attitude_noise_rad = 0.05 * units::kArcsecToRad;
  simulated_bench.navigation.scale_rw_rts = 0.0;
  expect_prediction_holds("navigation", pipeline::Stage::Navigation, 100.0, 20, Check::ErrorsAndSigmas,
                          simulated_bench,
                          [&](std::mt19937_64& rng) { return navigation_start(truth_body, rng); }, truth_body);
}

// The navigation program without its fast oscillations (parts 2 and 3): what the slow swings leave
// almost at its initial sigma plan names, with the motion that would determine it; the whole
// program leaves nothing weak.
TEST(PlanLong, WithoutTheFastOscillationsPlanNamesWhatIsLeftWeak) {
  json program = json::parse(motion::builtin_program_json("navigation"));
  json kept = json::array();
  for (const json& s : program.at("segments")) {
    const std::string name = s.value("name", "");
    if (name.find("osc") == std::string::npos && name.find("diagonal") == std::string::npos) kept.push_back(s);
  }
  ASSERT_LT(kept.size(), program.at("segments").size());
  program["segments"] = kept;
  program["name"] = "navigation-swings-only";
  const motion::Program p = motion::compile_program(program.dump(), motion::TableLimits{});
  plan::Options opt;
  opt.rate_hz = 20.0;
  const plan::Prediction prediction = plan::predict(p, nav_grade(), opt);
  const auto nav = std::find_if(prediction.stages.begin(), prediction.stages.end(),
                                [](const plan::StagePrediction& s) { return s.stage == "navigation"; });
  ASSERT_NE(nav, prediction.stages.end());
  EXPECT_EQ(nav->status, "done") << nav->message;
  std::map<std::string, std::string> weak;
  for (const plan::Weak& w : prediction.weak)
    if (w.stage == "navigation") {
      weak[w.coefficient] = w.fix;
      std::printf("  weak: %s: %s\n", w.coefficient.c_str(), w.why.c_str());
    }
  // The swings alone leave the y gyro's delay and a proof-mass offset almost where they started.
  for (const char* name : {"gyro.delay_us.y", "accel.lever_arm_mm.z.x"}) {
    ASSERT_TRUE(weak.count(name)) << name << " not named weak";
    EXPECT_NE(weak[name].find("fast oscillations"), std::string::npos) << weak[name];
  }
  // The whole program (with its fast oscillations) determines them: nothing is named.
  const plan::Prediction whole = plan::predict(motion::load_program("navigation", motion::TableLimits{}), nav_grade(), opt);
  for (const plan::Weak& w : whole.weak) ADD_FAILURE() << "the navigation program leaves " << w.coefficient << " weak: " << w.why;
  // What the swings do determine is not named.
  EXPECT_FALSE(weak.count("gyro.bias_dph.x"));
  EXPECT_FALSE(weak.count("accel.scale_ppm.z"));
}


// The optimizer (issue 16): from the built-in `navigation` program, a shorter program that meets
// the seed's stage-3 figures by prediction; that program simulated at 100 Hz and calibrated by
// stage 3 meets them in fact: every coefficient within three times its target (the limits the
// suite uses everywhere: three times the seed's 1-sigma).
TEST(PlanLong, TheOptimizerFindsAShorterProgramThatMeetsTheSeedsFigures) {
  const ImuModel truth = nav_grade();
  const ImuModel truth_body = direct::to_body_frame(truth);
  const json navigation = json::parse(motion::builtin_program_json("navigation"));
  plan::OptimizeOptions opt;
  opt.predict.rate_hz = 20.0;
  opt.budget_s = 240.0;
  // The simulated bench's g is exact (as TheDirectProgramDeliversWhatWasPredicted tells stage 1):
  // with normal gravity's 3e-4 m/s^2 stage 3's accelerometer scale factors would be known to 30
  // ppm whatever the program, and no program would meet the seed's figures.
  opt.predict.settings.navigation.gravity_sigma_mps2 = 0.0;
  const plan::Targets targets = plan::seed_targets();
  const plan::OptimizeResult r = plan::optimize(navigation, truth, targets, motion::TableLimits{}, opt);
  ASSERT_TRUE(r.best.has_value()) << "closest: worst " << r.closest.worst_ratio << " (" << r.closest.worst_coefficient << ")";
  const plan::Candidate& best = *r.best;
  std::printf("best of %d programs: %.0f s of %.0f s (swings x%.3f, oscillations x%.3f), predicted worst %.2f (%s)\n",
              r.evaluated, best.duration_s, r.reference.duration_s, best.swing_period_factor, best.oscillation_factor,
              best.worst_ratio, best.worst_coefficient.c_str());
  EXPECT_LT(best.duration_s, 0.8 * r.reference.duration_s);
  EXPECT_LE(best.worst_ratio, 1.0);

  std::mt19937_64 rng(2026);
  const motion::Program program = motion::compile_program(best.program_json, motion::TableLimits{});
  std::shared_ptr<const sim::MotionSignal> signal;
  const ImuModel got = calibrate(program, truth, pipeline::Stage::Navigation, 100.0, 7, navigation_start(truth_body, rng),
                                 opt.predict.settings, signal);
  const json est = pipeline::estimates_json(got);
  ImuModel named = truth_body;
  named.sigma = got.sigma;
  const json truth_values = pipeline::estimates_json(named);
  int judged = 0;
  double worst = 0;
  for (const auto& [name, pair] : est.items()) {
    const auto t = targets.find(name.substr(0, name.rfind('.')));
    if (t == targets.end() || !(pair.at(1).get<double>() > 0)) continue;  // no target, or fixed by the frame
    const double err = pair.at(0).get<double>() - truth_values.at(name).at(0).get<double>();
    const double ratio = std::abs(err) / (3.0 * t->second);
    worst = std::max(worst, ratio);
    ++judged;
    std::printf("  %-30s error %10.3g  limit %8.3g  ratio %5.2f\n", name.c_str(), err, 3.0 * t->second, ratio);
    EXPECT_LE(ratio, 1.0) << name << ": error " << err << " beyond three times its target " << t->second;
  }
  EXPECT_EQ(judged, 27);  // gyro bias, scales +-, 6 angles, delays; accelerometer bias, scale, 3 angles
  std::printf("the optimized program calibrated at 100 Hz: %d coefficients, worst error %.2f of its limit\n", judged, worst);
}

// Stage 3's budget and the bench it needs (issue 34): `navigation` planned on a table certified to
// 1" with a measured g, the prediction (the filter's covariance, its consider parameters the
// table's classes and the g) names each coefficient's dominant source and the largest 1-sigma of
// each class that keeps every coefficient within stage 3's limits (navfilter::Limits, the delays
// included). Each share is taken to scale with its sigma; the filter weighs a worse table's
// attitude less, so that errs on the safe side: planned again with the whole certificate scaled by
// the stated factor, no coefficient exceeds its limit.
TEST(PlanLong, StageThreeStatesItsBenchRequirements) {
  const motion::Program program = motion::load_program("navigation", motion::TableLimits{});
  plan::Options opt;
  opt.rate_hz = 50.0;
  opt.table = plan::uniform_table_certificate(1.0);
  opt.settings.navigation.gravity_sigma_mps2 = 1e-6;
  opt.settings.direct.gravity_sigma_mps2 = 1e-6;
  const plan::Prediction p = plan::predict(program, nav_grade(), opt);
  const json j = p.to_json();
  const json& nav = j.at("stages").at("navigation");
  ASSERT_TRUE(nav.contains("budget") && nav.contains("requirements")) << nav.dump().substr(0, 400);
  const json& req = nav.at("requirements");
  EXPECT_EQ(req.at("limits").at("gyro.delay_us"), 3.0);
  EXPECT_EQ(req.at("sources").size(), 7u);  // six table classes and the g
  std::size_t table_dominated = 0;
  for (const auto& [name, b] : nav.at("budget").items())
    table_dominated += b.at("dominant").get<std::string>().rfind("table.", 0) == 0;
  std::printf("stage 3 on a 1\" table: %zu of %zu coefficients dominated by the table\n", table_dominated,
              nav.at("budget").size());
  for (const json& r : req.at("sources")) std::printf("  %s\n", r.dump().c_str());
  ASSERT_FALSE(req.at("whole_table").is_null());
  const double factor = req.at("whole_table").at("max_factor").get<double>();
  std::printf("the whole certificate may be scaled by %.3g (%s)\n", factor,
              req.at("whole_table").at("limiting").get<std::string>().c_str());
  ASSERT_GT(factor, 0.0);

  opt.table = plan::uniform_table_certificate(std::min(factor, 10.0));
  const plan::Prediction at = plan::predict(program, nav_grade(), opt);
  const plan::StagePrediction& s3 = at.stages.back();
  ASSERT_EQ(s3.stage, "navigation");
  ASSERT_FALSE(s3.budget.empty());
  double worst = 0.0;
  const plan::Targets limits = plan::stage3_limits();
  for (const plan::CoefficientBudget& c : s3.budget)
    if (limits.contains(c.group)) worst = std::max(worst, c.combined / limits.at(c.group));
  std::printf("planned again at that table: worst coefficient at %.3f of its limit\n", worst);
  EXPECT_LE(worst, 1.0 + 1e-6);
}
