// The navigation floor: an error-free IMU through the navigation program, 2 h at 1 kHz.
#include <gtest/gtest.h>

#include "nav_fixture.hpp"

using namespace imucal;

TEST(NavigationLong, ErrorFreeImuThroughTheNavigationProgram) {
  const auto p = motion::load_program("navigation", motion::TableLimits{});
  sim::SimConfig cfg;
  cfg.rate_hz = 1000;
  cfg.duration_s = 7200;
  cfg.mount.r0_p_m << 0.03, -0.02, 0.05;
  const auto r = navtest::simulate_and_navigate(p, ImuModel{}, ImuModel{}, cfg, 10.0);
  RecordProperty("max_velocity_error_mps", std::to_string(r.summary.max_velocity_error_mps));
  RecordProperty("max_position_error_m", std::to_string(r.summary.max_position_error_m));
  std::printf("2 h navigation program at 1 kHz: max horizontal velocity error %.3e m/s, position %.3e m, "
              "attitude %.3e rad\n",
              r.summary.max_velocity_error_mps, r.summary.max_position_error_m, r.summary.max_attitude_error_rad);
  EXPECT_NEAR(r.summary.duration_s, 7200.0, 0.01);
  EXPECT_LT(r.summary.max_velocity_error_mps, 0.5e-3);
  EXPECT_LT(r.summary.max_position_error_m, 0.5);
}
