// Issue 19's acceptance: leaving the nonlinear terms out of a model when the IMU has them is
// visible in the Schuler test of the evaluate program. The truth has every term at the sizes the
// issue names (gyro nonlinearity 5-20 ppm at 300 deg/s, K2 20-50 ug/g^2, K3 1-5 ug/g^3,
// g-sensitivity 0.001-0.01 deg/h/g); the model "with" is the truth, "without" the truth less them.
#include <gtest/gtest.h>

#include <algorithm>
#include <cstdio>
#include <vector>

#include "sim/simulator.hpp"
#include "estimators/evaluate.hpp"
#include "motion_programs/program.hpp"

using namespace imucal;

TEST(EvaluateNonlinear, LeavingTheTermsOutShowsInTheSchulerTest) {
  using namespace units;
  ImuModel truth;
  truth.gyro.bias_radps = Eigen::Vector3d(0.05, -0.03, 0.02) * kDphToRadps;
  truth.gyro.scale_pos = Eigen::Vector3d(20, -15, 10) * kPpm;
  truth.gyro.scale_neg = Eigen::Vector3d(22, -14, 11) * kPpm;
  // c1 q + c2 q^2 + c3 q^3, q = |w| / 100 deg/s: 5.7, 9.0 and 15.9 ppm at 300 deg/s.
  truth.gyro.scale_nonlinear << 2.0, 0.8, 0.1, -1.5, 0.6, 0.3, 2.5, -0.8, 0.2;
  truth.gyro.scale_nonlinear *= kPpm;
  truth.gyro.g_sensitivity_radps_per_g << 0.008, -0.002, 0.005, 0.001, 0.006, -0.009, -0.004, 0.003, 0.010;
  truth.gyro.g_sensitivity_radps_per_g *= kDphToRadps;
  truth.accel.bias_mps2 = Eigen::Vector3d(1e-4, -2e-4, 1.5e-4);
  truth.accel.scale = Eigen::Vector3d(30, -20, 25) * kPpm;
  truth.accel.k2_per_g = Eigen::Vector3d(30, -45, 22) * 1e-6;
  truth.accel.k3_per_g2 = Eigen::Vector3d(2.0, -4.5, 1.2) * 1e-6;
  ImuModel without = truth;
  without.gyro.scale_nonlinear.setZero();
  without.gyro.g_sensitivity_radps_per_g.setZero();
  without.accel.k2_per_g.setZero();
  without.accel.k3_per_g2.setZero();

  const motion::Program p = motion::load_program("evaluate", motion::TableLimits{});
  sim::SimConfig cfg;
  cfg.rate_hz = 50;
  cfg.site.middle_axis_azimuth_deg = 15;
  sim::Simulator sim(p, truth, cfg);  // no noise: the figures are the models' alone
  const RecordingMeta meta = sim.meta();
  std::vector<ImuFrame> frames;
  ImuFrame f;
  while (sim.next(f)) frames.push_back(f);
  const auto judge = [&](const ImuModel& m) {
    return evaluate::evaluate_model(meta, m, [&](const auto& fn, std::int64_t t0, std::int64_t t1) {
      for (const ImuFrame& fr : frames)
        if (fr.t_ns >= t0 && fr.t_ns <= t1) fn(fr);
    });
  };
  const evaluate::Result with = judge(truth), wo = judge(without);
  for (const auto& [name, r] : {std::pair{"with the terms", with}, std::pair{"without them", wo}})
    std::printf("%-15s tilt Schuler amplitude %.5f m/s (accel error %.2e m/s^2), coning %.5f m/s (drift %.5f deg/h)\n", name,
                r.tilt_amplitude_mps, r.implied_accel_error_mps2, r.coning_amplitude_mps,
                r.implied_gyro_drift_radps * kRadpsToDph);
  // Measured at 50 Hz: with the terms 0.002 m/s on tilts and on coning (the discretisation floor of
  // the navigation at this rate: 0.03 m/s at 20 Hz); without them 0.32 and 0.31 m/s, the coning's
  // implied drift 0.0098 deg/h against 0.00001.
  EXPECT_GT(wo.tilt_amplitude_mps, 10.0 * with.tilt_amplitude_mps + 0.01);
  EXPECT_GT(wo.coning_amplitude_mps, 10.0 * with.coning_amplitude_mps + 0.01);

  // Which term shows where: each left out alone (docs/calibration.md quotes these).
  ImuModel no_k = truth, no_g = truth, no_nl = truth;
  no_k.accel.k2_per_g.setZero();
  no_k.accel.k3_per_g2.setZero();
  no_g.gyro.g_sensitivity_radps_per_g.setZero();
  no_nl.gyro.scale_nonlinear.setZero();
  for (const auto& [name, m] : {std::pair{"without K2, K3", no_k}, std::pair{"without g-sens.", no_g}, std::pair{"without nonlin.", no_nl}}) {
    const evaluate::Result r = judge(m);
    std::printf("%-15s tilt Schuler amplitude %.5f m/s (accel error %.2e m/s^2), coning %.5f m/s (drift %.5f deg/h)\n", name,
                r.tilt_amplitude_mps, r.implied_accel_error_mps2, r.coning_amplitude_mps,
                r.implied_gyro_drift_radps * kRadpsToDph);
    // Every term is worth having: each alone leaves more than the complete model.
    EXPECT_GT(std::max(r.tilt_amplitude_mps, r.coning_amplitude_mps), 2.0 * std::max(with.tilt_amplitude_mps, with.coning_amplitude_mps)) << name;
  }
}
