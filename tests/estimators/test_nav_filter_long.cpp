// Stage 3 acceptance: the navigation program at 1 kHz, errors against the seed's figures (x3).
#include <gtest/gtest.h>

#include "nav_calib_fixture.hpp"

using namespace imucal;
#ifndef RATE
#define RATE 1000
#endif


TEST(NavFilterLong, RefinesEveryCoefficientOnTheNavigationProgram) {
  const auto s = navcaltest::make_scenario(1, RATE);
  const navfilter::Result r = navcaltest::run_filter(s, "navigation", 1);
  std::printf("status: %s; updates %lld, rejected %lld, restarts %lld\n", r.status.c_str(),
              static_cast<long long>(r.updates), static_cast<long long>(r.rejected), static_cast<long long>(r.restarts));
  ASSERT_TRUE(r.converged) << r.status;
  navcaltest::expect_stage3_limits(s.truth_body, r.model);
  const ImuModel& t = s.truth_body;
  const double tau_yx = t.gyro.delay_s[1] - t.gyro.delay_s[0], tau_zx = t.gyro.delay_s[2] - t.gyro.delay_s[0];
  EXPECT_LE(std::abs(r.tau_yx_s - tau_yx) * 1e6, 0.6);
  EXPECT_LE(std::abs(r.tau_zx_s - tau_zx) * 1e6, 0.6);
}
