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
