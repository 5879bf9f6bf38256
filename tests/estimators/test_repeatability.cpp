// Turn-on to turn-on bias repeatability (IEEE 952) against simulated truth: the simulator draws a
// bias offset at each power-on (the run's start and each power-cycle segment).
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <stdexcept>

#include "calib_fixture.hpp"
#include "core/turn_on.hpp"
#include "estimators/repeatability.hpp"
#include "sim_run.hpp"

using namespace imucal;

namespace {

// A navigation-grade unit whose gyro biases move 0.01-0.03 deg/h and accelerometer biases
// 10-20 ug from one power-on to the next, with a warm-up the settle holds leave out.
ImuModel repeatability_truth() {
  ImuModel m = calibtest::random_stage1_imu(51);
  TurnOnSection s;
  s.value.gyro_repeatability_radps = Eigen::Vector3d(0.02, 0.01, 0.03) * units::kDphToRadps;
  s.value.accel_repeatability_mps2 = Eigen::Vector3d(10, 20, 15) * 1e-6 * units::kStandardGravity_mps2;
  s.value.gyro_warm_up_radps = Eigen::Vector3d(0.05, 0.05, 0.05) * units::kDphToRadps;
  s.value.gyro_time_constant_s = Eigen::Vector3d(5, 5, 5);
  set_turn_on(m, s);
  return m;
}

repeatability::Result run(const std::string& program, const ImuModel& truth, std::uint64_t seed) {
  return simrun::simulate_into<repeatability::RepeatabilityEstimator>(program, truth, 10, seed,
                                                                       [](auto& est) { return est.finish(); });
}

double truth_of(const ImuModel& truth, const repeatability::Channel& ch) {
  const auto turn_on = turn_on_of(truth);
  if (!turn_on) throw std::logic_error("the test's truth has no turn-on section");  // repeatability_truth() gives it one
  const TurnOnTerms t = turn_on->value;
  return ch.gyro ? t.gyro_repeatability_radps[ch.axis] : t.accel_repeatability_mps2[ch.axis];
}

}  // namespace

TEST(Repeatability, EachPowerOnsBiasIsTheOneTheSimulatorDrew) {
  // Without noise each power-on's static mean differs from the first by exactly the offsets drawn.
  ImuModel truth = repeatability_truth();
  truth.gyro.noise = {};
  truth.accel.noise = {};
  const repeatability::Result r = run("repeatability-short", truth, 7);
  ASSERT_EQ(r.turn_ons.size(), 6u);
  for (std::size_t k = 0; k < r.turn_ons.size(); ++k) EXPECT_EQ(r.turn_ons[k].index, static_cast<int>(k) + 1);
  for (const repeatability::Channel& ch : r.channels) {
    EXPECT_GT(ch.spread, 0.2 * truth_of(truth, ch)) << "the power-ons differ";
    EXPECT_LT(ch.noise, 1e-3 * truth_of(truth, ch)) << "without noise the statics' means are exact";
  }
}

namespace {

// The model's turn-on section, with a sigma, carries the z gyro's repeatability. (A function of
// its own: the test's body with it took clang-tidy's optional analysis past a minute.)
void expect_turn_on_repeatability(const ImuModel& model, double gyro_z_repeatability) {
  const auto s = turn_on_of(model);
  ASSERT_TRUE(s && s->sigma);
  EXPECT_EQ(s->value.gyro_repeatability_radps[2], gyro_z_repeatability);
}

}  // namespace

TEST(Repeatability, RecoversEveryChannelWithinItsSigma) {
  const ImuModel truth = repeatability_truth();
  const repeatability::Result r = run("repeatability", truth, 3);
  ASSERT_EQ(r.turn_ons.size(), 8u);
  for (const auto& n : r.notes) std::printf("%s\n", n.c_str());
  for (const repeatability::Channel& ch : r.channels) {
    const double k = ch.gyro ? units::kRadpsToDph : 1e6 / units::kStandardGravity_mps2;
    std::printf("  %s %c repeatability %.5f +- %.5f (truth %.5f) %s, spread %.5f, noise %.5f\n", ch.gyro ? "gyro " : "accel",
                "xyz"[ch.axis], ch.repeatability * k, ch.repeatability_sigma * k, truth_of(truth, ch) * k,
                ch.gyro ? "deg/h" : "ug", ch.spread * k, ch.noise * k);
    ASSERT_GT(ch.repeatability_sigma, 0.0);
    // Within the 3-sigma (99.73 %) interval of a standard deviation from 8 power-ons.
    EXPECT_GE(truth_of(truth, ch), ch.lo997);
    EXPECT_LE(truth_of(truth, ch), ch.hi997);
    EXPECT_LE(ch.lo68, ch.repeatability);
    EXPECT_GE(ch.hi68, ch.repeatability);
  }
  expect_turn_on_repeatability(r.model, r.channels[2].repeatability);
}

TEST(Repeatability, TheIntervalsHoldTheTruthAsOftenAsTheySayOver40Seeds) {
  // A standard deviation of six power-ons: its 68 % interval holds the truth about 68 % of the
  // time (240 channels: 1 sigma of the count is 3 %), its 99.73 % interval nearly always.
  const ImuModel truth = repeatability_truth();
  int inside68 = 0, outside997 = 0, n = 0;
  for (std::uint64_t seed = 200; seed < 240; ++seed) {
    const repeatability::Result r = run("repeatability-short", truth, seed);
    for (const repeatability::Channel& ch : r.channels) {
      const double t = truth_of(truth, ch);
      inside68 += ch.lo68 <= t && t <= ch.hi68;
      outside997 += t < ch.lo997 || t > ch.hi997;
      ++n;
    }
  }
  const double coverage = static_cast<double>(inside68) / n;
  std::printf("68 %% interval held the truth in %d of %d channels (%.3f); the 99.73 %% interval missed %d\n", inside68, n,
              coverage, outside997);
  EXPECT_GT(coverage, 0.58);
  EXPECT_LT(coverage, 0.78);
  EXPECT_LE(outside997, 3);
}

TEST(Repeatability, TooFewPowerOnsAreNamed) {
  try {
    run("warm-up-short", repeatability_truth(), 1);
    FAIL() << "one power-on cannot give a repeatability";
  } catch (const std::runtime_error& e) {
    const std::string what = e.what();
    EXPECT_NE(what.find("at least 3"), std::string::npos) << what;
    EXPECT_NE(what.find("program 'repeatability'"), std::string::npos) << what;
  }
}
