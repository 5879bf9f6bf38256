// Noise from statics: ARW and VRW within 10 %, bias instability within 30 % on the noise program.
#include <gtest/gtest.h>

#include "core/units.hpp"
#include "sim/simulator.hpp"
#include "estimators/noise.hpp"
#include "storage/bundle.hpp"

#include <filesystem>
#include "tests/test_paths.hpp"

using namespace imucal;

namespace {
noise::Result analyse(const motion::Program& p, const ImuModel& truth, double rate_hz, double duration_s) {
  sim::SimConfig cfg;
  cfg.rate_hz = rate_hz;
  cfg.seed = 9;
  cfg.duration_s = duration_s;
  sim::Simulator s(p, truth, cfg);
  noise::NoiseAnalyzer a(s.meta());
  ImuFrame f;
  while (s.next(f)) a.push(f);
  return a.finish();
}

ImuModel noisy_imu() {
  ImuModel m;
  m.gyro.noise.arw_rad_rts = 0.0005 * units::kDegRthToRadRts;
  m.gyro.noise.bias_instability_radps = 0.003 * units::kDphToRadps;
  m.accel.noise.vrw_mps_rts = 0.002 * units::kMpsRthToMpsRts;
  m.accel.noise.bias_instability_mps2 = 5e-6;
  return m;
}
}  // namespace

TEST(Noise, AllanDeviationOfWhiteNoiseFallsAsOneOverRootTau) {
  std::vector<double> y(200000);
  sim::NormalStream n(5);
  for (double& v : y) v = n.next();
  const auto adev = noise::overlapping_adev(y, 0.01, {1, 10, 100, 1000});
  for (std::size_t i = 0; i < 4; ++i) EXPECT_NEAR(adev[i] * std::sqrt(std::pow(10.0, i)), 1.0, 0.05) << i;
}

TEST(Noise, RandomWalksFromTheDirectProgramStatics) {
  const ImuModel truth = noisy_imu();
  const auto r = analyse(motion::load_program("direct", motion::TableLimits{}), truth, 100, 0);
  const ImuModel m = r.apply(ImuModel{});
  EXPECT_NEAR(m.gyro.noise.arw_rad_rts / truth.gyro.noise.arw_rad_rts, 1.0, 0.10);
  EXPECT_NEAR(m.accel.noise.vrw_mps_rts / truth.accel.noise.vrw_mps_rts, 1.0, 0.10);
  EXPECT_EQ(m.gyro.noise.bias_instability_radps, 0.0) << "36 s statics cannot show a bias floor";
}

// The independent recording: its statics end exactly where its moves end, on the same instant.
TEST(Noise, IndependentRecordingGivesItsTruthNoise) {
  const std::string db = imucaltest::test_tmp_dir() + "/noise-example.db";
  std::filesystem::create_directories(imucaltest::test_tmp_dir());
  std::filesystem::remove(db);
  storage::import_bundle(imucaltest::test_data_dir() + "/example-direct", db);
  const auto run = storage::RunDb::open(db);
  noise::NoiseAnalyzer a(run.meta());
  run.for_each_frame([&](const ImuFrame& f) { a.push(f); });
  const ImuModel m = a.finish().apply(ImuModel{});
  const ImuModel truth = read_imu_model_file(imucaltest::test_data_dir() + "/example-direct/truth.json");
  EXPECT_NEAR(m.gyro.noise.arw_rad_rts / truth.gyro.noise.arw_rad_rts, 1.0, 0.10);
  EXPECT_NEAR(m.accel.noise.vrw_mps_rts / truth.accel.noise.vrw_mps_rts, 1.0, 0.10);
}
