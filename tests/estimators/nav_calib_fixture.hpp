// Stage-3 scenario: a navigation-grade IMU, a stage-1 model with the seed's residual errors.
#pragma once

#include <random>

#include "calib_fixture.hpp"
#include "drivers/sim/simulator.hpp"
#include "estimators/direct_calibration.hpp"
#include "estimators/nav_filter.hpp"

namespace imucal::navcaltest {

struct Scenario {
  ImuModel truth;        // instrument frame, with delays and lever arms
  ImuModel truth_body;   // the same in the body frame
  ImuModel stage1_body;  // truth_body plus the residual errors stage 3 starts from
  sim::SimConfig cfg;
};

inline Scenario make_scenario(unsigned seed, double rate_hz) {
  using namespace units;
  Scenario s;
  s.truth = calibtest::random_stage1_imu(seed);
  s.truth.gyro.delay_s << 2e-6, 5e-6, -3e-6;
  s.truth.accel.delay_s << 2.0e-3, 2.1e-3, 1.9e-3;
  s.truth.accel.lever_arm_y_m << 0.010, -0.004, 0.006;
  s.truth.accel.lever_arm_z_m << -0.005, 0.008, -0.012;
  // Biases drifting as slow random walks.
  s.truth.gyro.noise.rate_random_walk_radps_rts = 0.0005 * kDphToRadps / 60.0;  // 0.0005 deg/h/rt-h
  s.truth.accel.noise.accel_random_walk_mps2_rts = 2e-6 / 60.0;                 // 2e-6 m/s^2/rt-h
  s.truth.mount_r0_p_m = Eigen::Vector3d(0.03, -0.02, 0.05);
  s.truth_body = direct::to_body_frame(s.truth);
  std::mt19937_64 rng(seed * 7919u + 1);
  std::normal_distribution<double> n01;
  ImuModel m = s.truth_body;
  for (int j = 0; j < 3; ++j) {
    m.gyro.bias_radps[j] += 0.01 * kDphToRadps * n01(rng);
    m.gyro.scale_pos[j] += 1e-5 * n01(rng);
    m.gyro.scale_neg[j] += 1e-5 * n01(rng);
    m.accel.bias_mps2[j] += 1e-3 * n01(rng);
    m.accel.scale[j] += 1e-5 * n01(rng);
  }
  for (const MisalignmentKey& key : kMisalignmentKeys)
    m.gyro.misalignment_rad.*key.member += 3.0 * kArcsecToRad * n01(rng);
  for (double Misalignment::*k : {&Misalignment::yz, &Misalignment::zx, &Misalignment::zy})
    m.accel.misalignment_rad.*k += 3.0 * kArcsecToRad * n01(rng);
  m.gyro.delay_s.setZero();
  m.accel.delay_s.setZero();
  m.sigma.reset();
  s.stage1_body = m;
  s.cfg.rate_hz = rate_hz;
  s.cfg.seed = seed;
  s.cfg.site.middle_axis_azimuth_deg = 25;
  s.cfg.mount.r0_p_m = *s.truth.mount_r0_p_m;
  return s;
}

// stochastic_bias_end: when given, receives the random part of the true biases at the end of the
// run (the filter tracks drifting biases, so that is what it should have found).
inline navfilter::Result run_filter(const Scenario& s, const std::string& program, int passes = 1,
                                    double duration_s = 0, Eigen::Matrix<double, 6, 1>* stochastic_bias_end = nullptr) {
  const auto p = motion::load_program(program, motion::TableLimits{});
  sim::SimConfig cfg = s.cfg;
  cfg.duration_s = duration_s;
  ImuModel truth_sim = s.truth;
  truth_sim.mount_r0_p_m.reset();
  const RecordingMeta meta = sim::Simulator(p, truth_sim, cfg).meta();
  ImuModel model = s.stage1_body;
  model.mount_r0_p_m = cfg.mount.r0_p_m;
  return navfilter::calibrate_offline(
      meta, model,
      [&](const auto& fn) {
        sim::Simulator sim(p, truth_sim, cfg);
        ImuFrame f;
        while (sim.next(f)) fn(f);
        if (stochastic_bias_end) *stochastic_bias_end = sim.stochastic_bias();
      },
      passes);
}

}  // namespace imucal::navcaltest
