// The built-in thermal campaign on the daemon's simulated bench: `{"program": "thermal-short"}`
// brings its chamber profile, the bench follows it with the thermal model (chamber air, case,
// each sensor, and a truth whose coefficients depend on T and dT/dt), and the run's thermal plots
// show the sensors crossing the profile's range and stage 2 taking most of the temperature
// dependence out. thermal-short: 2 h of program at 20 Hz, as fast as possible.
#include <gtest/gtest.h>

#include <algorithm>

#include "service_fixture.hpp"
#include "tests/test_paths.hpp"

using namespace imucal;
using namespace imucal::daemontest;

TEST(DaemonThermal, TheBuiltInThermalCampaignFollowsItsChamberProfileAndFeedsStageTwo) {
  // The truth by name from a truths folder (a campaign names no path): examples/truth-thermal.json.
  LocalDaemon d("thermal", false, [](daemon::DaemonConfig& c) { c.sim.truths_dir = imucaltest::source_dir() + "/examples"; });
  const std::string truth = "truth-thermal";
  const auto id = d.post_campaign(
      {{"name", "overnight"}, {"program", "thermal-short"}, {"truth", truth}, {"rate_hz", 20}, {"time_scale", 0}});
  // The campaign as stored: the profile's set points as steps, with the ramp tolerance.
  const json stored = d.campaign(id);
  const json chamber = stored.at("spec").at("chamber");
  EXPECT_EQ(chamber.at("setpoint_C").get<double>(), 25.0);
  EXPECT_GE(chamber.at("tolerance_C").get<double>(), 5.0);
  ASSERT_GE(chamber.at("steps").size(), 3u) << chamber.dump();
  double lo = 1e9, hi = -1e9;
  for (const auto& s : chamber.at("steps")) {
    lo = std::min(lo, s.at("setpoint_C").get<double>());
    hi = std::max(hi, s.at("setpoint_C").get<double>());
  }
  EXPECT_EQ(lo, 15.0);
  EXPECT_EQ(hi, 35.0);

  // The campaign builder sees the same chamber with the built-in program.
  bool listed = false;
  const json programs = d.get("/api/programs");
  for (const auto& p : programs.at("programs"))
    if (p.at("name") == "thermal-short") {
      listed = true;
      EXPECT_EQ(p.at("chamber"), chamber);
    }
  EXPECT_TRUE(listed) << programs.dump().substr(0, 300);

  ASSERT_EQ(d.command(id, "start"), 200);
  const json done = d.wait_final(id, 600.0);
  ASSERT_EQ(done.at("state"), "done") << done.dump().substr(0, 2000);

  const auto reply = d.get_computed("/api/campaigns/" + std::to_string(id) + "/thermal");
  ASSERT_EQ(reply.status, 200) << reply.body.substr(0, 1000);
  const json thermal = json::parse(reply.body);
  EXPECT_EQ(thermal.at("residual_source"), "truth");
  EXPECT_EQ(thermal.at("cycles_used").get<int>(), thermal.at("cycles_total").get<int>());
  // The FOG x coil's temperature over the cycles: across most of 15..35 C (it lags the air).
  const json& T = thermal.at("coefficients").at("gyro.bias_dph.x").at("T_C");
  const auto [tmin, tmax] = std::minmax_element(T.begin(), T.end(), [](const json& a, const json& b) {
    return a.get<double>() < b.get<double>();
  });
  std::printf("FOG x coil over the cycles: %.2f .. %.2f C\n", tmin->get<double>(), tmax->get<double>());
  EXPECT_LT(tmin->get<double>(), 19.0);
  EXPECT_GT(tmax->get<double>(), 31.0);
  // The truth follows the temperatures, and stage 2 takes most of that out again (2 h is too
  // little coverage for the seed's figures; docs/thermal.md).
  for (const char* group : {"accel.bias_mps2", "accel.scale_ppm", "gyro.bias_dph"}) {
    const double before = thermal.at("before").at(group).get<double>();
    const double after = thermal.at("residual").at(group).get<double>();
    std::printf("%-18s before %.4g, after %.4g\n", group, before, after);
    EXPECT_LT(after, 0.3 * before) << group;
  }
}
