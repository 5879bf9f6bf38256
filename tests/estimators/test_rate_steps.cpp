// The rate-steps test (IEEE 952 scale factor per rate, asymmetry, nonlinearity, scale_nonlinear_ppm)
// against simulated truth.
#include "rate_steps_fixture.hpp"

using namespace imucal;
using namespace imucal::ratestepstest;

TEST(RateSteps, ShortLadderRecoversScalePerRateAsymmetryAndQuadraticNonlinearity) {
  const ImuModel truth = nonlinear_truth();
  const rate_steps::Result r = run_rate_steps("rate-steps-short", truth, 100, 3);
  expect_truth_within_3_sigma(truth, r, 16);
  // No nonlinearity invented where there is none; the ones there are found.
  EXPECT_EQ(r.axes[0].degree, 0);
  EXPECT_EQ(r.axes[1].degree, 2);
  EXPECT_EQ(r.axes[2].degree, 2);
}

// Nine rates pin down a cubic term the five of the short ladder cannot tell from noise.
TEST(RateSteps, FullLadderFindsACubicTerm) {
  ImuModel truth = nonlinear_truth();
  truth.gyro.scale_nonlinear.row(2) = Eigen::RowVector3d(-2.0, 2.0, 0.3) * 1e-6;  // 20 ppm at 300 deg/s
  const rate_steps::Result r = run_rate_steps("rate-steps", truth, 100, 5);
  expect_truth_within_3_sigma(truth, r, 22);
  EXPECT_EQ(r.axes[0].degree, 0);
  EXPECT_EQ(r.axes[2].degree, 3);
}

// The short ladder finds a pure cubic (issue 34: c3 = 0.2 ppm, 5.4 ppm at 300 deg/s): noise-free,
// degree 3 predicts the held-back rates to 1e-6 ppm against 0.25 ppm for degree 2, yet the paired
// test over six interior rates alone cannot exceed 1.92 standard errors and kept degree 2.
TEST(RateSteps, ShortLadderFindsACubicTheDataHolds) {
  ImuModel truth = calibtest::random_stage1_imu(23);
  truth.gyro.noise = GyroNoise{};
  truth.accel.noise = AccelNoise{};
  truth.gyro.scale_nonlinear.row(2) = Eigen::RowVector3d(0.0, 0.0, 0.2) * 1e-6;
  const rate_steps::Result r = run_rate_steps("rate-steps-short", truth, 100, 5);
  for (const auto& ax : r.axes) {
    std::printf("degree %d, held-back rms by degree:", ax.degree);
    for (const auto& sc : ax.scores) std::printf(" %d: %.2e ppm", sc.degree, sc.held_back_rms_ppm);
    std::printf("\n");
  }
  EXPECT_EQ(r.axes[0].degree, 0);
  EXPECT_EQ(r.axes[1].degree, 0);
  EXPECT_EQ(r.axes[2].degree, 3);
  EXPECT_NEAR(r.model.gyro.scale_nonlinear(2, 2) * 1e6, 0.2, 0.01);
}

TEST(RateSteps, AProgramWithoutALadderIsNamed) {
  const ImuModel truth = calibtest::random_stage1_imu(22);
  try {
    run_rate_steps("direct-short", truth, 20, 4);
    FAIL() << "direct-short has one rate per axis: the test must refuse it";
  } catch (const std::runtime_error& e) {
    const std::string what = e.what();
    EXPECT_NE(what.find("three rates"), std::string::npos) << what;
    EXPECT_NE(what.find("rate-steps"), std::string::npos) << what;
  }
}
