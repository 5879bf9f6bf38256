// The multipoint tumble (IEEE 1293): accelerometer bias, scale, K2, K3 and angles, gyro bias and
// g-sensitivity, against simulated truth.
#include "tumble_fixture.hpp"

using namespace imucal;
using namespace imucal::tumbletest;

TEST(Tumble, RecoversAccelerometerK2K3AndGyroGSensitivity) {
  const ImuModel truth = tumble_truth();
  const tumble::Result r = run_tumble("tumble", truth, 100, 7);
  for (const auto& n : r.notes) std::printf("%s\n", n.c_str());
  ASSERT_TRUE(r.model.sigma.has_value());
  EXPECT_EQ(r.positions.size(), 48u);
  Check check;
  check_all(check, truth, r);
  // The seed's figure for an accelerometer bias, 5e-6 m/s^2.
  for (int j = 0; j < 3; ++j) EXPECT_LE(r.model.sigma->accel.bias_mps2[j], 5e-6);
}

TEST(Tumble, TooFewStaticsAreNamed) {
  const ImuModel truth = calibtest::random_stage1_imu(32);
  try {
    run_tumble("rate-steps-short", truth, 20, 3);
    FAIL() << "rate-steps-short has statics in three orientations only: the tumble must refuse it";
  } catch (const std::runtime_error& e) {
    const std::string what = e.what();
    EXPECT_NE(what.find("tumble"), std::string::npos) << what;
    std::printf("%s\n", what.c_str());
  }
}
