// Stage 3 on issue 14's stress case (slow): proof masses 30-50 mm from the origin, axis angles of
// 40-60", scale errors of 200-300 ppm, the navigation program's fast 180 deg oscillations, sensor
// noise and drifting biases; started from a stage-1 model with the seed's residuals and the proof
// masses known to 0.1 mm. Every coefficient within three times the seed's 1-sigma, at 100 and
// 200 Hz, with the filter's default (real-table) tuning.
#include <gtest/gtest.h>

#include "nav_calib_fixture.hpp"

using namespace imucal;

namespace {
void stress_case(double rate_hz) {
  const auto s = navcaltest::make_stress_scenario(1, rate_hz);
  Eigen::Matrix<double, 6, 1> drift = Eigen::Matrix<double, 6, 1>::Zero();
  const navfilter::Result r = navcaltest::run_filter(s, "navigation", 1, 0, &drift);
  ASSERT_TRUE(r.converged) << r.status;
  std::printf("%.0f Hz: %lld updates, %lld rejected, %lld restarts\n", rate_hz, static_cast<long long>(r.updates),
              static_cast<long long>(r.rejected), static_cast<long long>(r.restarts));
  // The biases drift: the filter should end at the truth plus the drift.
  ImuModel truth = s.truth_body;
  truth.gyro.bias_radps += drift.head<3>();
  truth.accel.bias_mps2 += drift.tail<3>();
  navcaltest::expect_stage3_limits(truth, r.model);
  const double tau_yx = truth.gyro.delay_s[1] - truth.gyro.delay_s[0], tau_zx = truth.gyro.delay_s[2] - truth.gyro.delay_s[0];
  std::printf("tau_yx err %+.3f us (sigma %.3f), tau_zx err %+.3f us (sigma %.3f)\n", (r.tau_yx_s - tau_yx) * 1e6,
              r.sigma_tau_yx_s * 1e6, (r.tau_zx_s - tau_zx) * 1e6, r.sigma_tau_zx_s * 1e6);
  // The relative gyro delays: with this IMU's noise the program gives them to ~0.28 us (1 sigma),
  // not the seed's 0.2 us; the errors must lie within 3 of that sigma.
  EXPECT_LE(r.sigma_tau_yx_s * 1e6, 0.3);
  EXPECT_LE(r.sigma_tau_zx_s * 1e6, 0.3);
  EXPECT_LE(std::abs(r.tau_yx_s - tau_yx), 3 * r.sigma_tau_yx_s);
  EXPECT_LE(std::abs(r.tau_zx_s - tau_zx), 3 * r.sigma_tau_zx_s);
}
}  // namespace

TEST(NavFilterStress, At100Hz) { stress_case(100); }
TEST(NavFilterStress, At200Hz) { stress_case(200); }
