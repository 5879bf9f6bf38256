// The seed's judgement of a calibration (slow): direct, plus size effect, plus navigation
// refinement, each judged by free-inertial navigation on the evaluate program.
#include <gtest/gtest.h>

#include "estimators/direct_calibration.hpp"
#include "estimators/evaluate.hpp"
#include "estimators/lever_arm.hpp"
#include "nav_calib_fixture.hpp"

using namespace imucal;

namespace {

template <class Consumer>
RecordingMeta simulate(const std::string& program, const navcaltest::Scenario& s, Consumer&& consume,
                       std::uint64_t seed) {
  const auto p = motion::load_program(program, motion::TableLimits{});
  sim::SimConfig cfg = s.cfg;
  cfg.seed = seed;
  ImuModel truth = s.truth;
  truth.mount_r0_p_m.reset();
  sim::Simulator sim(p, truth, cfg);
  const RecordingMeta meta = sim.meta();
  ImuFrame f;
  consume(meta, [&](const auto& fn) {
    sim::Simulator again(p, truth, cfg);
    while (again.next(f)) fn(f);
  });
  return meta;
}

}  // namespace

TEST(EvaluateLong, ThreeVariantsOnTheEvaluateProgram) {
  using namespace units;
  const auto s = navcaltest::make_scenario(5, 200);
  // Variant 1: stage 1 alone (direct program).
  ImuModel direct_model;
  simulate("direct", s, [&](const RecordingMeta& meta, const auto& frames) {
    direct::DirectCalibrator cal(meta);
    frames([&](const ImuFrame& f) { cal.push(f); });
    direct_model = cal.finish().model;
  }, 11);
  // Variant 2: plus the size effect (lever-arm program).
  ImuModel size_model;
  simulate("lever-arm", s, [&](const RecordingMeta& meta, const auto& frames) {
    lever::LeverArmFilter filter(meta, direct_model);
    frames([&](const ImuFrame& f) { filter.push(f); });
    size_model = filter.finish().model;
  }, 12);
  // Variant 3: plus the navigation-solution refinement (navigation program), in the body frame.
  ImuModel refined;
  simulate("navigation", s, [&](const RecordingMeta& meta, const auto& frames) {
    const navfilter::Result r = navfilter::calibrate_offline(meta, size_model, frames, 1);
    ASSERT_TRUE(r.converged) << r.status;
    refined = r.model;
  }, 13);
  // Judge all three on the evaluate program.
  std::vector<evaluate::Result> results;
  simulate("evaluate", s, [&](const RecordingMeta& meta, const auto&) {
    const auto p = motion::load_program("evaluate", motion::TableLimits{});
    sim::SimConfig cfg = s.cfg;
    cfg.seed = 14;
    ImuModel truth = s.truth;
    truth.mount_r0_p_m.reset();
    // Simulate once into memory-light chunks per segment: replay from the start for each range.
    for (const ImuModel* m : {&direct_model, &size_model, &refined})
      results.push_back(evaluate::evaluate_model(meta, *m, [&](const auto& fn, std::int64_t t0, std::int64_t t1) {
        sim::Simulator sim(p, truth, cfg);
        ImuFrame f;
        while (sim.next(f)) {
          if (f.t_ns < t0) continue;
          if (f.t_ns > t1) break;
          fn(f);
        }
      }));
  }, 14);
  const char* names[3] = {"direct", "size effect", "navigation"};
  for (int i = 0; i < 3; ++i)
    std::printf("%-12s tilt amplitude %.5f m/s (accel %.2e m/s^2)  coning amplitude %.5f m/s (drift %.5f deg/h)\n",
                names[i], results[i].tilt_amplitude_mps, results[i].implied_accel_error_mps2,
                results[i].coning_amplitude_mps, results[i].implied_gyro_drift_radps * kRadpsToDph);
  std::printf("ratios direct/refined: tilt %.1f, coning %.1f\n",
              results[0].tilt_amplitude_mps / results[2].tilt_amplitude_mps,
              results[0].coning_amplitude_mps / results[2].coning_amplitude_mps);
  EXPECT_LT(results[2].implied_gyro_drift_radps * kRadpsToDph, 0.003);
  EXPECT_LT(results[2].implied_accel_error_mps2, 1.5e-5);
  EXPECT_LT(results[2].coning_amplitude_mps, results[0].coning_amplitude_mps);
}
