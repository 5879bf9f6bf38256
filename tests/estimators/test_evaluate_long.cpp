// The seed's judgement of a calibration (slow): direct, plus size effect, plus navigation
// refinement, each judged by free-inertial navigation on the evaluate program.
#include <gtest/gtest.h>

#include "estimators/direct_calibration.hpp"
#include "estimators/evaluate.hpp"
#include "estimators/lever_arm.hpp"
#include "nav_calib_fixture.hpp"

using namespace imucal;

namespace {

// The random-walk biases at the end of the last simulated run: the evaluate run continues the same
// IMU from there.
Eigen::Matrix<double, 6, 1> g_bias_end = Eigen::Matrix<double, 6, 1>::Zero();

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
    g_bias_end = again.stochastic_bias();
  });
  return meta;
}

}  // namespace

TEST(EvaluateLong, ThreeVariantsOnTheEvaluateProgram) {
  using namespace units;
  const auto s = navcaltest::make_scenario(5, 1000);  // 1 kHz, as the stage-3 acceptance
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
  // Judge all three on the evaluate program, simulated once into memory, the IMU's drifting biases
  // continuing from the end of the navigation run. The acceptance figures come from a run without
  // the random noise (coefficients, delays, lever arms and the biases reached are all there): over
  // a 30 min tilt, an ARW of 0.0005 deg/rt-h alone tilts the platform by ~6e-6 rad, a floor of
  // ~2e-5 m/s^2 on the implied accelerometer error whatever the calibration. The noisy figures
  // are printed beside them. The two runs differ by the noise alone: the second shares the first's
  // motion signal (sim::MotionSignal).
  std::shared_ptr<const sim::MotionSignal> signal;
  auto judge = [&](bool with_noise) {
    const auto p = motion::load_program("evaluate", motion::TableLimits{});
    sim::SimConfig cfg = s.cfg;
    cfg.seed = 14;
    ImuModel truth = s.truth;
    truth.mount_r0_p_m.reset();
    if (!with_noise) {
      truth.gyro.noise = {};
      truth.accel.noise = {};
    }
    sim::Simulator sim(p, truth, cfg);
    if (!signal) signal = sim.motion_signal();
    sim.use_motion_signal(signal);
    sim.continue_stochastic_bias(g_bias_end);  // the same IMU, right after the navigation run
    const RecordingMeta meta = sim.meta();
    std::vector<ImuFrame> frames;
    ImuFrame f;
    while (sim.next(f)) frames.push_back(f);
    std::vector<evaluate::Result> out;
    for (const ImuModel* m : {&direct_model, &size_model, &refined})
      out.push_back(evaluate::evaluate_model(meta, *m, [&](const auto& fn, std::int64_t t0, std::int64_t t1) {
        for (const ImuFrame& fr : frames)
          if (fr.t_ns >= t0 && fr.t_ns <= t1) fn(fr);
      }));
    return out;
  };
  const std::vector<evaluate::Result> noisy = judge(true);
  const std::vector<evaluate::Result> results = judge(false);
  for (int i = 0; i < 3; ++i)
    std::printf("with noise: %d tilt amplitude %.5f m/s (accel %.2e)  coning amplitude %.5f m/s (drift %.5f deg/h)\n", i,
                noisy[static_cast<std::size_t>(i)].tilt_amplitude_mps,
                noisy[static_cast<std::size_t>(i)].implied_accel_error_mps2,
                noisy[static_cast<std::size_t>(i)].coning_amplitude_mps,
                noisy[static_cast<std::size_t>(i)].implied_gyro_drift_radps * kRadpsToDph);
  const char* names[3] = {"direct", "size effect", "navigation"};
  for (int i = 0; i < 3; ++i)
    std::printf("noise-free: %-12s tilt amplitude %.5f m/s (accel %.2e m/s^2)  coning amplitude %.5f m/s (drift %.5f deg/h)\n",
                names[i], results[static_cast<std::size_t>(i)].tilt_amplitude_mps, results[static_cast<std::size_t>(i)].implied_accel_error_mps2,
                results[static_cast<std::size_t>(i)].coning_amplitude_mps, results[static_cast<std::size_t>(i)].implied_gyro_drift_radps * kRadpsToDph);
  std::printf("ratios direct/refined: tilt %.1f, coning %.1f\n",
              results[0].tilt_amplitude_mps / results[2].tilt_amplitude_mps,
              results[0].coning_amplitude_mps / results[2].coning_amplitude_mps);
  // The acceptance, on the noise-free judgement: the refined model's implied residual gyro
  // drift (coning) below 0.003 deg/h and residual accelerometer error (tilts) below 1.5e-5 m/s^2.
  // Measured: 0.0008 deg/h and 7.4e-6 m/s^2. Coning is what makes the first hard: its rectified
  // rates (mean |w| 0.07 rad/s on the two swinging axes, 0.0096 rad/s along the third) turn 0.1 ppm
  // of gyro scale asymmetry into ~0.0015 deg/h and 0.1" of gyro axis angle into ~0.001 deg/h.
  EXPECT_LT(results[2].implied_gyro_drift_radps * kRadpsToDph, 0.003);
  EXPECT_LT(results[2].implied_accel_error_mps2, 1.5e-5);
  // And the refinement must pay: the refined model beats stage 1 alone on coning by a clear margin
  // (measured 10x noise-free).
  EXPECT_LT(results[2].coning_amplitude_mps, 0.3 * results[0].coning_amplitude_mps);
  EXPECT_LT(noisy[2].coning_amplitude_mps, 0.7 * noisy[0].coning_amplitude_mps);
}
