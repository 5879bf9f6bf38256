// The warm-up test (IEEE 952): each channel's bias transient from power-on, its time constant and
// the time to settle within a band, against simulated truth; the model's turn-on section.
#include "warm_up_fixture.hpp"

#include <stdexcept>

using namespace imucal;
using namespace imucal::warmuptest;

TEST(TurnOn, TheSectionRoundTripsThroughTheModelAndIsChecked) {
  const ImuModel truth = warm_up_truth();
  const ImuModel back = imu_model_from_json_text(imu_model_to_json_text(truth), "truth.json");
  const auto s = turn_on_of(back);
  ASSERT_TRUE(s.has_value());
  EXPECT_NEAR(s->value.gyro_warm_up_radps[2] * units::kRadpsToDph, 0.06, 1e-12);
  EXPECT_EQ(s->value.accel_time_constant_s[1], 240.0);
  EXPECT_FALSE(turn_on_of(ImuModel{}).has_value());
  const auto refused = [](const std::string& turn_on) {
    try {
      imu_model_from_json_text(R"({"format": "imucal-imu-model/1", "turn_on": )" + turn_on + "}", "m.json");
    } catch (const std::runtime_error& e) {
      return std::string(e.what());
    }
    return std::string("accepted");
  };
  EXPECT_EQ(refused(R"({"gyro": {"warm_up_dhp": [1, 0, 0]}})"),
            "m.json.turn_on.gyro: unknown key \"warm_up_dhp\"");
  EXPECT_EQ(refused(R"({"accel": {"warm_up_mps2": [0, 1e-5, 0]}})"),
            "m.json.turn_on.accel.warm_up_time_constant_s[1]: must be positive where warm_up_mps2 is not zero");
  EXPECT_EQ(refused(R"({"gyro": {"bias_repeatability_dph": [0, -1, 0]}})"),
            "m.json.turn_on.gyro.bias_repeatability_dph[1]: must not be negative (a 1-sigma)");
}

TEST(WarmUp, TheSimulatorAddsTheTransientFromPowerOn) {
  // Without noise the fit returns the truth's transient to the precision of the quantisation.
  ImuModel truth = warm_up_truth();
  truth.gyro.noise = {};
  truth.accel.noise = {};
  const warm_up::Result r = run_warm_up("warm-up-short", truth, 10, 1);
  const TurnOnTerms t = turn_on_of(truth)->value;
  for (const warm_up::Channel& ch : r.channels) {
    const double amp = ch.gyro ? t.gyro_warm_up_radps[ch.axis] : t.accel_warm_up_mps2[ch.axis];
    const double tau = ch.gyro ? t.gyro_time_constant_s[ch.axis] : t.accel_time_constant_s[ch.axis];
    EXPECT_NEAR(ch.amplitude / amp, 1.0, 1e-4) << (ch.gyro ? "gyro " : "accel ") << ch.axis;
    EXPECT_NEAR(ch.time_constant_s / tau, 1.0, 1e-4) << (ch.gyro ? "gyro " : "accel ") << ch.axis;
  }
}

TEST(WarmUp, RecoversEveryChannelsTransientWithinItsSigma) {
  const ImuModel truth = warm_up_truth();
  const warm_up::Result r = run_warm_up("warm-up-short", truth, 10, 3);
  for (const auto& n : r.notes) std::printf("%s\n", n.c_str());
  Scores scores;
  check_channels(truth, r, scores, true);
  // The model carries what was found, with its sigma, for the unit's record.
  const auto s = turn_on_of(r.model);
  ASSERT_TRUE(s.has_value());
  const auto& s_sigma = s->sigma;
  ASSERT_TRUE(s_sigma.has_value());
  EXPECT_EQ(s->value.gyro_warm_up_radps[0], r.channels[0].amplitude);
  EXPECT_EQ(s_sigma->accel_time_constant_s[2], r.channels[5].time_constant_sigma_s);
}

TEST(WarmUp, AnImuThatDoesNotWarmUpShowsNoTransient) {
  const ImuModel truth = calibtest::random_stage1_imu(42);
  const warm_up::Result r = run_warm_up("warm-up-short", truth, 10, 5);
  for (const warm_up::Channel& ch : r.channels) {
    EXPECT_FALSE(ch.detected) << (ch.gyro ? "gyro " : "accel ") << ch.axis << ": chi2 gain " << ch.chi2_gain;
    EXPECT_EQ(ch.settle_time_s, 0.0);
  }
  const auto s = turn_on_of(r.model);
  ASSERT_TRUE(s.has_value());
  EXPECT_TRUE(s->value.gyro_warm_up_radps.isZero(0.0));
  EXPECT_TRUE(s->value.accel_warm_up_mps2.isZero(0.0));
  EXPECT_EQ(r.notes.size(), 6u) << "each channel says it found no transient";
}

TEST(WarmUp, StaticsAtSeveralOrientationsAreRefusedByName) {
  try {
    run_warm_up("tumble-short", calibtest::random_stage1_imu(43), 10, 1);
    FAIL() << "the tumble's statics are at 24 orientations: the warm-up must refuse them";
  } catch (const std::runtime_error& e) {
    const std::string what = e.what();
    EXPECT_NE(what.find("stage warm-up"), std::string::npos) << what;
    EXPECT_NE(what.find("program 'warm-up'"), std::string::npos) << what;
    std::printf("%s\n", what.c_str());
  }
}

TEST(WarmUp, ErrorsScatterAsTheSigmasSayOver20Seeds) {
  // The 2 h program (1.6 s of simulation in all): every channel's amplitude and time constant,
  // error over sigma, RMS near 1.
  const ImuModel truth = warm_up_truth();
  Scores scores;
  for (std::uint64_t seed = 100; seed < 120; ++seed) check_channels(truth, run_warm_up("warm-up", truth, 10, seed), scores, false);
  const double rms = std::sqrt(scores.sum_z2 / scores.n);
  std::printf("error/sigma RMS over %d estimates: %.2f\n", scores.n, rms);
  EXPECT_GT(rms, 0.7);
  EXPECT_LT(rms, 1.4);
}
