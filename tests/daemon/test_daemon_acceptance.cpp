// Acceptance limits, verdicts, comparisons and repeatability as pure functions of model JSON
// (daemon/production/acceptance.hpp); the daemon's endpoints are tested in test_daemon_units.cpp.
#include <gtest/gtest.h>

#include <cmath>
#include <set>

#include "daemon/production/acceptance.hpp"
#include "daemon/production/test_report.hpp"

using namespace imucal::daemon;
using nlohmann::json;

namespace {

// A direct-stage result: biases and scale factors determined, delays carried over (sigma 0).
json result_model(double bias_x_dph, double sigma_x_dph) {
  return {{"format", "imucal-imu-model/1"},
          {"frame", "instrument"},
          {"gyro",
           {{"bias_dph", {bias_x_dph, -0.002, 0.003}},
            {"scale_pos_ppm", {10.0, 20.0, 30.0}},
            {"delay_us", {0.0, 0.0, 0.0}},
            {"noise", {{"arw_deg_rth", 0.0005}, {"bias_instability_dph", 0.0}}}}},
          {"accel", {{"bias_mps2", {1e-4, 2e-4, -3e-4}}}},
          {"sigma",
           {{"gyro", {{"bias_dph", {sigma_x_dph, 0.001, 0.001}}, {"scale_pos_ppm", {0.5, 0.5, 0.5}}, {"delay_us", {0.0, 0.0, 0.0}}}},
            {"accel", {{"bias_mps2", {5e-6, 5e-6, 5e-6}}}}}}};
}

json limits_file(const json& entries) {
  return {{"format", "imucal-limits/1"}, {"part_numbers", {{"PN-1", entries}}}};
}

const json* row(const json& rows, const std::string& key) {
  for (const json& r : rows)
    if (r.at("key") == key) return &r;
  return nullptr;
}

}  // namespace

TEST(Acceptance, AGroupLimitAppliesToEveryAxisAndTheMostSpecificKeyWins) {
  const auto parts = limits_from_json(limits_file({{"gyro.bias_dph", {{"max_abs", 0.005}, {"max_sigma", 0.002}}},
                                                   {"gyro.bias_dph.z", {{"max_abs", 0.001}}}}));
  const json v = verdict_json(result_model(0.004, 0.001), parts.at("PN-1"), "limits.json");
  EXPECT_FALSE(v.at("pass").get<bool>());
  EXPECT_EQ(v.at("failures"), 1);
  EXPECT_EQ(v.at("coefficients").size(), 3u);
  EXPECT_TRUE(row(v.at("coefficients"), "gyro.bias_dph.x")->at("pass").get<bool>());
  EXPECT_EQ(row(v.at("coefficients"), "gyro.bias_dph.x")->at("limit_sigma"), 0.002);
  const json& z = *row(v.at("coefficients"), "gyro.bias_dph.z");
  EXPECT_FALSE(z.at("pass").get<bool>());
  EXPECT_TRUE(z.at("limit_sigma").is_null());  // the z key replaces the group's limit whole
  EXPECT_NE(z.at("reason").get<std::string>().find("|value| 0.003 > limit 0.001"), std::string::npos) << z;
  EXPECT_EQ(v.at("limits"), "limits.json");
  EXPECT_EQ(v.at("part_number"), "PN-1");
}

TEST(Acceptance, ASigmaBeyondItsLimitFails) {
  const auto parts = limits_from_json(limits_file({{"gyro.bias_dph.x", {{"max_sigma", 0.002}}}}));
  EXPECT_TRUE(verdict_json(result_model(0.5, 0.0019), parts.at("PN-1"), "f").at("pass").get<bool>());
  const json v = verdict_json(result_model(0.5, 0.0021), parts.at("PN-1"), "f");
  EXPECT_FALSE(v.at("pass").get<bool>());
  EXPECT_NE(v.at("coefficients")[0].at("reason").get<std::string>().find("sigma 0.0021 > limit 0.002"), std::string::npos);
}

TEST(Acceptance, ALimitedCoefficientTheRunDidNotDetermineFails) {
  // Delays carried over with sigma 0, a bias instability the run did not estimate (0), a
  // coefficient the model does not carry at all (no row: nothing was judged on it).
  const auto parts = limits_from_json(limits_file({{"gyro.delay_us", {{"max_abs", 100}}},
                                                   {"gyro.noise.bias_instability_dph", {{"max_abs", 0.01}}},
                                                   {"gyro.noise.arw_deg_rth", {{"max_abs", 0.001}}}}));
  const json v = verdict_json(result_model(0.0, 0.001), parts.at("PN-1"), "f");
  EXPECT_EQ(v.at("failures"), 4);
  EXPECT_EQ(row(v.at("coefficients"), "gyro.delay_us.y")->at("reason"), "not determined by this run");
  EXPECT_EQ(row(v.at("coefficients"), "gyro.noise.bias_instability_dph")->at("reason"), "not determined by this run");
  EXPECT_TRUE(row(v.at("coefficients"), "gyro.noise.arw_deg_rth")->at("pass").get<bool>());
}

TEST(Acceptance, BadLimitsAreRefusedNamingTheEntry) {
  auto message = [](const json& file) {
    try {
      limits_from_json(file);
    } catch (const std::invalid_argument& e) {
      return std::string(e.what());
    }
    return std::string("accepted");
  };
  EXPECT_NE(message(limits_file({{"gyro.bais_dph", {{"max_abs", 1}}}})).find("[\"gyro.bais_dph\"]: no coefficient"), std::string::npos);
  EXPECT_NE(message(limits_file({{"gyro.bias", {{"max_abs", 1}}}})).find("no coefficient"), std::string::npos);
  EXPECT_NE(message(limits_file({{"gyro.bias_dph", {{"max_abs", -1}}}})).find("max_abs must be a positive number"), std::string::npos);
  EXPECT_NE(message(limits_file({{"gyro.bias_dph", {{"max", 1}}}})).find("unknown key \"max\""), std::string::npos);
  EXPECT_NE(message(limits_file({{"gyro.bias_dph", json::object()}})).find("neither max_abs nor max_sigma"), std::string::npos);
  EXPECT_NE(message(limits_file({{"gyro.noise.arw_deg_rth", {{"max_sigma", 1}}}})).find("noise terms carry no sigma"), std::string::npos);
  EXPECT_NE(message({{"format", "imucal-limits/2"}}).find("format"), std::string::npos);
  EXPECT_NE(message({{"format", "imucal-limits/1"}, {"parts", json::object()}}).find("limits: unknown key \"parts\""), std::string::npos);
  // A round trip keeps every limit.
  const json good = limits_file({{"accel.misalignment_arcsec.yz", {{"max_abs", 30}, {"max_sigma", 0.3}}},
                                 {"gyro.scale_pos_ppm", {{"max_sigma", 0.5}}}});
  EXPECT_EQ(limits_to_json(limits_from_json(good)), good);
}

TEST(Acceptance, TwoCalibrationsDifferInCombinedSigmas) {
  const json a = result_model(0.010, 0.003), b = result_model(0.030, 0.004);
  const json c = compare_json(a, b);
  const json& x = *row(c.at("coefficients"), "gyro.bias_dph.x");
  EXPECT_DOUBLE_EQ(x.at("difference").get<double>(), 0.020);
  EXPECT_DOUBLE_EQ(x.at("combined_sigma").get<double>(), 0.005);
  EXPECT_NEAR(x.at("in_sigmas").get<double>(), 4.0, 1e-12);
  EXPECT_TRUE(x.at("significant").get<bool>());
  EXPECT_FALSE(row(c.at("coefficients"), "gyro.bias_dph.y")->at("significant").get<bool>());
  EXPECT_EQ(c.at("significant"), 1);
  EXPECT_EQ(row(c.at("coefficients"), "gyro.delay_us.x"), nullptr);  // neither run determined it
  EXPECT_TRUE(row(c.at("coefficients"), "gyro.noise.arw_deg_rth")->at("significant").is_null());
}

TEST(Acceptance, RepeatabilityIsTheSampleStandardDeviationOverRuns) {
  const json r = repeatability_json({result_model(0.010, 0.001), result_model(0.012, 0.001), result_model(0.017, 0.001)});
  const json& x = r.at("gyro.bias_dph.x");
  EXPECT_EQ(x.at("n"), 3);
  EXPECT_NEAR(x.at("mean").get<double>(), 0.013, 1e-15);
  EXPECT_NEAR(x.at("std").get<double>(), std::sqrt((9e-6 + 1e-6 + 16e-6) / 2.0), 1e-15);
  EXPECT_FALSE(r.contains("gyro.delay_us.x"));
  EXPECT_TRUE(repeatability_json({result_model(0.01, 0.001)}).empty());  // one run: no spread
}

// The test report of a run whose stages are calibrations (lever-arm, direct): each estimate a
// figure. Its loop once ran over items() of a temporary (a crash of imucald on any lever-arm run's
// report, issue 33); under the sanitizers this reads freed memory if it comes back.
TEST(TestReport, ACalibrationStageListsEachEstimate) {
  const json detail = {{"id", 7},
                       {"results",
                        {{"lever-arm",
                          {{"status", "done"},
                           {"source", "parts 'lever-arm'"},
                           {"estimates", {{"accel.lever_arm_mm.y", {1.25, 0.02}}, {"accel.lever_arm_mm.z", {-0.5, 0.03}}}}}}}}};
  const json report = test_report_json(detail, json::object(), TemperatureSummary{});
  ASSERT_EQ(report.at("tests").size(), 1u);
  const json& figures = report.at("tests").at(0).at("figures");
  ASSERT_EQ(figures.size(), 2u);
  EXPECT_EQ(figures.at(0).at("key"), "accel.lever_arm_mm.y");
  EXPECT_DOUBLE_EQ(figures.at(0).at("value").get<double>(), 1.25);
  EXPECT_DOUBLE_EQ(figures.at(1).at("u").get<double>(), 0.03);
}

// A group's limit reaches the noise terms too, which carry no sigma: they are judged on max_abs
// alone (reading their absent sigma against max_sigma was undefined behaviour before).
TEST(Acceptance, AGroupSigmaLimitDoesNotApplyToANoiseTerm) {
  const auto parts = limits_from_json(limits_file({{"gyro", {{"max_abs", 1000}, {"max_sigma", 0.002}}}}));
  const json v = verdict_json(result_model(0.0, 0.001), parts.at("PN-1"), "f");
  const json& arw = *row(v.at("coefficients"), "gyro.noise.arw_deg_rth");
  EXPECT_TRUE(arw.at("pass").get<bool>()) << arw;
  EXPECT_EQ(arw.at("reason"), "") << arw;
  EXPECT_TRUE(arw.at("sigma").is_null());
  // The others under the group: judged on both limits as before.
  EXPECT_TRUE(row(v.at("coefficients"), "gyro.bias_dph.x")->at("pass").get<bool>());
  EXPECT_EQ(row(v.at("coefficients"), "gyro.noise.bias_instability_dph")->at("reason"), "not determined by this run");
}

// New limits supersede only the certificates of the part numbers whose limits changed.
TEST(Acceptance, OnlyThePartNumbersWhoseLimitsChangedAreNamed) {
  const json before = {{"format", "imucal-limits/1"},
                       {"part_numbers", {{"A", {{"gyro.bias_dph", {{"max_abs", 1.0}}}}},
                                         {"B", {{"gyro.bias_dph", {{"max_abs", 2.0}}}}},
                                         {"C", {{"accel.scale_ppm", {{"max_abs", 50.0}}}}}}}};
  json after = before;
  after["part_numbers"]["B"]["gyro.bias_dph"]["max_abs"] = 3.0;  // changed
  after["part_numbers"].erase("C");                              // removed
  after["part_numbers"]["D"] = {{"gyro.bias_dph", {{"max_abs", 1.0}}}};  // added
  EXPECT_EQ(changed_part_numbers(before, after), (std::set<std::string>{"B", "C", "D"}));
  EXPECT_TRUE(changed_part_numbers(before, before).empty());
  EXPECT_EQ(changed_part_numbers(json::object(), before), (std::set<std::string>{"A", "B", "C"}));
}
