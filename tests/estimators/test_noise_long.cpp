// Bias instability within 30 % on the 2 h noise program (slow).
#include <gtest/gtest.h>

#include "core/units.hpp"
#include "sim/simulator.hpp"
#include "estimators/noise.hpp"

using namespace imucal;

TEST(NoiseLong, BiasInstabilityFromTheNoiseProgram) {
  ImuModel truth;
  truth.gyro.noise.arw_rad_rts = 0.0005 * units::kDegRthToRadRts;
  truth.gyro.noise.bias_instability_radps = 0.003 * units::kDphToRadps;
  truth.accel.noise.vrw_mps_rts = 0.002 * units::kMpsRthToMpsRts;
  truth.accel.noise.bias_instability_mps2 = 5e-6;
  sim::SimConfig cfg;
  cfg.rate_hz = 200;
  cfg.seed = 10;
  const auto p = motion::load_program("noise", motion::TableLimits{});
  sim::Simulator s(p, truth, cfg);
  noise::NoiseAnalyzer a(s.meta());
  ImuFrame f;
  while (s.next(f)) a.push(f);
  const noise::Result r = a.finish();
  const ImuModel m = r.apply(ImuModel{});
  for (std::size_t c = 0; c < 6; ++c)
    std::printf("channel %zu: white %.4g, bias instability %.4g\n", c, r.channel[c].white, r.channel[c].bias_instability);
  EXPECT_NEAR(m.gyro.noise.arw_rad_rts / truth.gyro.noise.arw_rad_rts, 1.0, 0.10);
  EXPECT_NEAR(m.accel.noise.vrw_mps_rts / truth.accel.noise.vrw_mps_rts, 1.0, 0.10);
  EXPECT_NEAR(m.gyro.noise.bias_instability_radps / truth.gyro.noise.bias_instability_radps, 1.0, 0.30);
  EXPECT_NEAR(m.accel.noise.bias_instability_mps2 / truth.accel.noise.bias_instability_mps2, 1.0, 0.30);
}
