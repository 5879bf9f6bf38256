// Golden tests: each estimator on a fixed input; a change of its output beyond a small fraction of
// the output's own sigma fails. Regenerate deliberately with IMUCAL_UPDATE_GOLDEN=1 after a change
// that is meant to move the numbers, and say why in the commit.
#include <cstdlib>
#include <filesystem>
#include <fstream>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "calib_fixture.hpp"
#include "sim/simulator.hpp"
#include "estimators/direct_calibration.hpp"
#include "estimators/lever_arm.hpp"
#include "estimators/nav_filter.hpp"
#include "estimators/noise.hpp"
#include "lever_fixture.hpp"
#include "nav_calib_fixture.hpp"
#include "storage/bundle.hpp"
#include "tests/test_paths.hpp"

using namespace imucal;
using nlohmann::json;

namespace {

const std::string kGoldenDir = imucaltest::test_data_dir() + "/golden";

// values and tolerances are flat name -> number maps.
void check_golden(const std::string& name, const std::map<std::string, double>& values,
                  const std::map<std::string, double>& tolerance) {
  const std::string path = kGoldenDir + "/" + name + ".json";
  if (std::getenv("IMUCAL_UPDATE_GOLDEN")) {
    std::filesystem::create_directories(kGoldenDir);
    std::ofstream(path) << json(values).dump(1) << "\n";
    GTEST_SKIP() << "wrote " << path;
  }
  std::ifstream in(path);
  ASSERT_TRUE(in) << path << " missing: run with IMUCAL_UPDATE_GOLDEN=1 once";
  const json golden = json::parse(in);
  ASSERT_EQ(golden.size(), values.size()) << name;
  for (const auto& [key, value] : values) {
    ASSERT_TRUE(golden.contains(key)) << name << ": " << key;
    EXPECT_NEAR(value, golden[key].get<double>(), tolerance.at(key)) << name << ": " << key;
  }
}

// Every coefficient of a model, with 1 % of its sigma (or an absolute floor) as the tolerance.
void flatten(const ImuModel& m, std::map<std::string, double>& v, std::map<std::string, double>& tol) {
  const ImuErrorSet& s = *m.sigma;
  auto put = [&](const std::string& k, double value, double sigma) {
    v[k] = value;
    tol[k] = std::max(0.01 * sigma, 1e-15);
  };
  for (int j = 0; j < 3; ++j) {
    const std::string a = std::to_string(j);
    put("gyro.bias." + a, m.gyro.bias_radps[j], s.gyro.bias_radps[j]);
    put("gyro.scale_pos." + a, m.gyro.scale_pos[j], s.gyro.scale_pos[j]);
    put("gyro.scale_neg." + a, m.gyro.scale_neg[j], s.gyro.scale_neg[j]);
    put("gyro.delay." + a, m.gyro.delay_s[j], s.gyro.delay_s[j]);
    put("accel.bias." + a, m.accel.bias_mps2[j], s.accel.bias_mps2[j]);
    put("accel.scale." + a, m.accel.scale[j], s.accel.scale[j]);
    put("accel.delay." + a, m.accel.delay_s[j], s.accel.delay_s[j]);
    put("accel.lever_y." + a, m.accel.lever_arm_y_m[j], s.accel.lever_arm_y_m[j]);
    put("accel.lever_z." + a, m.accel.lever_arm_z_m[j], s.accel.lever_arm_z_m[j]);
  }
  for (const auto& [n, k] : kMisalignmentKeys) {
    put(std::string("gyro.angle.") + n, m.gyro.misalignment_rad.*k, s.gyro.misalignment_rad.*k);
    put(std::string("accel.angle.") + n, m.accel.misalignment_rad.*k, s.accel.misalignment_rad.*k);
  }
}

// Each test imports into its own file: ctest runs the tests of one executable in parallel.
storage::RunDb example_run(const std::string& name) {
  const std::string db = imucaltest::test_tmp_dir() + "/golden-" + name + ".db";
  std::filesystem::create_directories(imucaltest::test_tmp_dir());
  std::filesystem::remove(db);
  storage::import_bundle(imucaltest::test_data_dir() + "/example-direct", db);
  return storage::RunDb::open(db);
}

}  // namespace

TEST(Golden, DirectOnTheIndependentRecording) {
  const auto run = example_run("direct");
  direct::DirectCalibrator cal(run.meta());
  run.for_each_frame([&](const ImuFrame& f) { cal.push(f); });
  std::map<std::string, double> v, tol;
  flatten(cal.finish().model, v, tol);
  check_golden("direct-example", v, tol);
}

TEST(Golden, NoiseOnTheIndependentRecording) {
  const auto run = example_run("noise");
  noise::NoiseAnalyzer a(run.meta());
  run.for_each_frame([&](const ImuFrame& f) { a.push(f); });
  const noise::Result r = a.finish();
  std::map<std::string, double> v, tol;
  for (std::size_t c = 0; c < 6; ++c) {
    v["white." + std::to_string(c)] = r.channel[c].white;
    tol["white." + std::to_string(c)] = 1e-4 * r.channel[c].white;
    v["adev1." + std::to_string(c)] = r.channel[c].adev.at(5);
    tol["adev1." + std::to_string(c)] = 1e-4 * r.channel[c].adev.at(5);
  }
  check_golden("noise-example", v, tol);
}

TEST(Golden, LeverArmOnASimulatedRun) {
  const lever::Result r = levertest::run(levertest::make_run(calibtest::random_stage1_imu(31), {0.011, -0.003, 0.004},
                                                             {-0.007, 0.009, -0.010}, {0.02, 0.01, 0.04}, 100, 31));
  std::map<std::string, double> v, tol;
  for (int i = 0; i < 9; ++i) {
    v["rho." + std::to_string(i)] = r.state_m[i];
    tol["rho." + std::to_string(i)] = 0.01 * r.sigma_m[i];
  }
  check_golden("lever-arm-sim", v, tol);
}

TEST(Golden, NavigationFilterOnTwentyMinutes) {
  const auto s = navcaltest::make_scenario(41, 100);
  const navfilter::Result r = navcaltest::run_filter(s, "navigation", 1, 1200.0);
  ASSERT_TRUE(r.converged) << r.status;
  std::map<std::string, double> v, tol;
  flatten(r.model, v, tol);
  check_golden("nav-filter-sim", v, tol);
}
