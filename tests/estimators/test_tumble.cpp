// The multipoint tumble (IEEE 1293): accelerometer bias, scale, K2, K3 and angles, gyro bias and
// g-sensitivity, against simulated truth.
#include <tuple>

#include "core/earth.hpp"
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

// The vertical Earth rate turns with gravity through the whole tumble, so the prior's gyro
// misalignments and scale factors are confounded with the g-sensitivity (issue 34): without a
// stage-1 prior the tumble says so; with one, its sigma carries the prior's uncertainty.
TEST(Tumble, GSensitivityCarriesThePriorsUncertaintyOrSaysItHasNone) {
  const ImuModel truth = tumble_truth();
  auto finish_with = [&](const ImuModel& prior) {
    return simrun::simulate_into<tumble::TumbleEstimator>("tumble-short", truth, 50, 11,
                                                          [&](auto& est) { return est.finish(prior); });
  };
  auto says_confounded = [](const tumble::Result& r) {
    for (const auto& n : r.notes)
      if (n.find("no stage-1 model given") != std::string::npos) return true;
    return false;
  };
  const tumble::Result bare = finish_with(ImuModel{});
  EXPECT_TRUE(says_confounded(bare));
  // A prior 200" off in gyro x's angle xz (row x, column y of D) and 200 ppm in gyro z's scale, with
  // sigmas that say so: shifts of 0.013 and 0.003 deg/h/g, beyond the tumble-short's own 0.003
  // (without the prior's part in the sigma the first is 4 of them off).
  ImuModel prior;
  prior.gyro.scale_pos = truth.gyro.scale_pos;
  prior.gyro.scale_neg = truth.gyro.scale_neg;
  prior.gyro.misalignment_rad = truth.gyro.misalignment_rad;
  prior.gyro.misalignment_rad.xz += 200.0 * units::kArcsecToRad;
  prior.gyro.scale_pos[2] += 200e-6;
  prior.gyro.scale_neg[2] += 200e-6;
  prior.sigma = ImuErrorSet{};
  const double angle_sigma = 200 * units::kArcsecToRad;
  prior.sigma->gyro.misalignment_rad = {angle_sigma, angle_sigma, angle_sigma, angle_sigma, angle_sigma, angle_sigma};
  prior.sigma->gyro.scale_pos.setConstant(200e-6);
  prior.sigma->gyro.scale_neg.setConstant(200e-6);
  const tumble::Result r = finish_with(prior);
  EXPECT_FALSE(says_confounded(r));
  const ImuErrorSet& sg = *r.model.sigma;
  // The erroneous elements moved by about their error times the vertical Earth rate, and the
  // sigma covers it.
  const double v = earth::kOmega_radps * std::sin(Site{}.latitude_deg * units::kDegToRad);  // the simulator's site
  for (const auto& [j, k, err] : {std::tuple{0, 1, 200.0 * units::kArcsecToRad}, std::tuple{2, 2, 200e-6}}) {
    const double off = r.model.gyro.g_sensitivity_radps_per_g(j, k) - truth.gyro.g_sensitivity_radps_per_g(j, k);
    std::printf("g-sensitivity (%d,%d): off %.5f deg/h/g, sigma %.5f, expected shift %.5f\n", j, k,
                off * units::kRadpsToDph, sg.gyro.g_sensitivity_radps_per_g(j, k) * units::kRadpsToDph,
                err * v * units::kRadpsToDph);
    EXPECT_LE(std::abs(off), 3.0 * sg.gyro.g_sensitivity_radps_per_g(j, k));
    EXPECT_GE(sg.gyro.g_sensitivity_radps_per_g(j, k), err * v);
  }
}
