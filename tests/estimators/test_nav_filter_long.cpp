// Stage 3 acceptance: the navigation program at 1 kHz, errors against the seed's figures (x3).
#include <gtest/gtest.h>

#include "nav_calib_fixture.hpp"

using namespace imucal;
#ifndef RATE
#define RATE 1000
#endif

namespace {
void report(const navcaltest::Scenario& s, const navfilter::Result& r) {
  using namespace units;
  const ImuModel& t = s.truth_body;
  const ImuModel& e = r.model;
  std::printf("status: %s; updates %lld, rejected %lld, restarts %lld\n", r.status.c_str(),
              static_cast<long long>(r.updates), static_cast<long long>(r.rejected), static_cast<long long>(r.restarts));
  for (int j = 0; j < 3; ++j)
    std::printf("axis %d: gbias %+.5f dph (s %.5f)  g+ %+.3f ppm  g- %+.3f ppm  abias %+.2e  ascale %+.3f ppm  "
                "gdelay %+.3f us  adelay %+.1f us\n",
                j, (e.gyro.bias_radps[j] - t.gyro.bias_radps[j]) * kRadpsToDph, e.sigma->gyro.bias_radps[j] * kRadpsToDph,
                (e.gyro.scale_pos[j] - t.gyro.scale_pos[j]) * 1e6, (e.gyro.scale_neg[j] - t.gyro.scale_neg[j]) * 1e6,
                e.accel.bias_mps2[j] - t.accel.bias_mps2[j], (e.accel.scale[j] - t.accel.scale[j]) * 1e6,
                (e.gyro.delay_s[j] - t.gyro.delay_s[j]) * 1e6, (e.accel.delay_s[j] - t.accel.delay_s[j]) * 1e6);
  for (const auto& [n, k] : kMisalignmentKeys)
    std::printf("angle %s: gyro %+.3f\"  accel %+.3f\"\n", n, (e.gyro.misalignment_rad.*k - t.gyro.misalignment_rad.*k) * kRadToArcsec,
                (e.accel.misalignment_rad.*k - t.accel.misalignment_rad.*k) * kRadToArcsec);
}
}  // namespace

TEST(NavFilterLong, RefinesEveryCoefficientOnTheNavigationProgram) {
  using namespace units;
  const auto s = navcaltest::make_scenario(1, RATE);
  const navfilter::Result r = navcaltest::run_filter(s, "navigation", 1);
  report(s, r);
  ASSERT_TRUE(r.converged) << r.status;
  const ImuModel& t = s.truth_body;
  const ImuModel& e = r.model;
  for (int j = 0; j < 3; ++j) {
    EXPECT_LE(std::abs(e.gyro.bias_radps[j] - t.gyro.bias_radps[j]) * kRadpsToDph, 0.003) << j;
    EXPECT_LE(std::abs(e.gyro.scale_pos[j] - t.gyro.scale_pos[j]) * 1e6, 1.5) << j;
    EXPECT_LE(std::abs(e.gyro.scale_neg[j] - t.gyro.scale_neg[j]) * 1e6, 1.5) << j;
    EXPECT_LE(std::abs(e.accel.bias_mps2[j] - t.accel.bias_mps2[j]), 1.5e-5) << j;
    EXPECT_LE(std::abs(e.accel.scale[j] - t.accel.scale[j]) * 1e6, 0.9) << j;
    EXPECT_LE(std::abs(e.gyro.delay_s[j] - t.gyro.delay_s[j]) * 1e6, 3.0) << j;
    EXPECT_LE(std::abs(e.accel.delay_s[j] - t.accel.delay_s[j]) * 1e6, 50.0) << j;
  }
  for (const MisalignmentKey& key : kMisalignmentKeys)
    EXPECT_LE(std::abs(e.gyro.misalignment_rad.*key.member - t.gyro.misalignment_rad.*key.member) * kRadToArcsec, 0.3);
  for (double Misalignment::*k : {&Misalignment::yz, &Misalignment::zx, &Misalignment::zy})
    EXPECT_LE(std::abs(e.accel.misalignment_rad.*k - t.accel.misalignment_rad.*k) * kRadToArcsec, 0.9);
  const double tau_yx = t.gyro.delay_s[1] - t.gyro.delay_s[0], tau_zx = t.gyro.delay_s[2] - t.gyro.delay_s[0];
  EXPECT_LE(std::abs(r.tau_yx_s - tau_yx) * 1e6, 0.6);
  EXPECT_LE(std::abs(r.tau_zx_s - tau_zx) * 1e6, 0.6);
}
