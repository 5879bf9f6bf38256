// Simulated warm-ups and their comparison with the truth (test_warm_up).
#pragma once

#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <string>

#include "calib_fixture.hpp"
#include "core/turn_on.hpp"
#include "estimators/warm_up.hpp"
#include "sim_run.hpp"

namespace imucal::warmuptest {

// A navigation-grade unit (ARW 0.0005 deg/rt-h, VRW 0.002 m/s/rt-h) whose biases settle after
// power-on: gyros by 0.03-0.06 deg/h over 5-8 min, accelerometers by 6-10 ug over 4-10 min.
inline ImuModel warm_up_truth(unsigned seed = 41) {
  ImuModel m = calibtest::random_stage1_imu(seed);
  TurnOnSection s;
  s.value.gyro_warm_up_radps = Eigen::Vector3d(0.05, -0.03, 0.06) * units::kDphToRadps;
  s.value.gyro_time_constant_s = Eigen::Vector3d(300, 400, 480);
  s.value.accel_warm_up_mps2 = Eigen::Vector3d(8, -6, 10) * 1e-6 * units::kStandardGravity_mps2;
  s.value.accel_time_constant_s = Eigen::Vector3d(600, 240, 420);
  set_turn_on(m, s);
  return m;
}

inline warm_up::Result run_warm_up(const std::string& program, const ImuModel& truth, double rate_hz, std::uint64_t seed) {
  return simrun::simulate_into<warm_up::WarmUpEstimator>(program, truth, rate_hz, seed,
                                                          [](auto& est) { return est.finish(); });
}

// Each channel's amplitude, time constant and settle time against the truth, as error / sigma.
struct Scores {
  double sum_z2 = 0;
  int n = 0;
  void add(double z) {
    sum_z2 += z * z;
    ++n;
  }
};

inline void check_channels(const ImuModel& truth, const warm_up::Result& r, Scores& scores, bool verbose) {
  const auto turn_on = turn_on_of(truth);
  ASSERT_TRUE(turn_on.has_value()) << "the truth has no turn-on section";
  const TurnOnTerms t = turn_on->value;
  for (std::size_t c = 0; c < 6; ++c) {
    const warm_up::Channel& ch = r.channels[c];
    const int j = ch.axis;
    const double amp = ch.gyro ? t.gyro_warm_up_radps[j] : t.accel_warm_up_mps2[j];
    const double tau = ch.gyro ? t.gyro_time_constant_s[j] : t.accel_time_constant_s[j];
    const double settle = std::abs(amp) > ch.band ? tau * std::log(std::abs(amp) / ch.band) : 0.0;
    const double k = ch.gyro ? units::kRadpsToDph : 1e6 / units::kStandardGravity_mps2;
    const std::string name = std::string(ch.gyro ? "gyro " : "accel ") + "xyz"[j];
    if (verbose)
      std::printf("  %-8s amplitude %+9.5f (truth %+9.5f, sigma %.5f) %s, tau %6.1f s (truth %5.0f, sigma %5.1f), "
                  "settle %6.1f s (truth %6.1f, sigma %5.1f), chi2 gain %.0f\n",
                  name.c_str(), ch.amplitude * k, amp * k, ch.amplitude_sigma * k, ch.gyro ? "deg/h" : "ug",
                  ch.time_constant_s, tau, ch.time_constant_sigma_s, ch.settle_time_s, settle, ch.settle_time_sigma_s,
                  ch.chi2_gain);
    EXPECT_TRUE(ch.detected) << name;
    EXPECT_TRUE(ch.resolved) << name;
    ASSERT_GT(ch.amplitude_sigma, 0.0) << name;
    ASSERT_GT(ch.time_constant_sigma_s, 0.0) << name;
    const double z_amp = (ch.amplitude - amp) / ch.amplitude_sigma;
    const double z_tau = (ch.time_constant_s - tau) / ch.time_constant_sigma_s;
    const double z_settle = (ch.settle_time_s - settle) / ch.settle_time_sigma_s;
    scores.add(z_amp);
    scores.add(z_tau);
    if (verbose) {
      EXPECT_LE(std::abs(z_amp), 3.0) << name << " amplitude";
      EXPECT_LE(std::abs(z_tau), 3.0) << name << " time constant";
      EXPECT_LE(std::abs(z_settle), 3.0) << name << " settle time";
    }
  }
}

}  // namespace imucal::warmuptest
