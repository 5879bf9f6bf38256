// kill -9 during stage 3: the real imucald is killed while the navigation-solution filter runs on
// a `navigation` campaign, restarted, and the run resumed. The filter's state is not checkpointed:
// the resumed run's estimator worker reads the run file from its start (docs/daemon.md, crash
// recovery), so its model must equal an uninterrupted run's to within the filter's sigma (slow:
// two passes of the navigation program at 50 Hz).
#include <signal.h>

#include <fstream>

#include <gtest/gtest.h>

#include "service_fixture.hpp"
#include "subprocess.hpp"
#include "tests/test_paths.hpp"

using namespace imucal;
using namespace imucal::daemontest;

namespace {

using Daemon = DaemonProcess;
Daemon spawn(const std::string& data_dir, const std::string& log_path) {
  return spawn_imucald(imucaltest::program("imucald"), data_dir, log_path, kOperatorToken);
}

// The navigation-grade truth with stage 1's residual errors (seed ch. 4: 0.01 deg/h, 10 ppm,
// 1e-3 m/s^2, 3"), delays unknown: what stage 3 starts from.
json start_model() {
  std::ifstream in(imucaltest::source_dir() + "/examples/truth-nav-grade.json");
  json m = json::parse(in);
  const double sign[3] = {1, -1, 1};
  for (int j = 0; j < 3; ++j) {
    m["gyro"]["bias_dph"][j] = m["gyro"]["bias_dph"][j].get<double>() + 0.01 * sign[j];
    m["gyro"]["scale_pos_ppm"][j] = m["gyro"]["scale_pos_ppm"][j].get<double>() + 10 * sign[j];
    m["gyro"]["scale_neg_ppm"][j] = m["gyro"]["scale_neg_ppm"][j].get<double>() - 10 * sign[j];
    m["gyro"]["delay_us"][j] = 0.0;
    m["accel"]["bias_mps2"][j] = m["accel"]["bias_mps2"][j].get<double>() + 1e-3 * sign[j];
    m["accel"]["scale_ppm"][j] = m["accel"]["scale_ppm"][j].get<double>() - 10 * sign[j];
    m["accel"]["delay_us"][j] = 0.0;
  }
  for (auto& [k, v] : m["gyro"]["misalignment_arcsec"].items()) v = v.get<double>() + 3.0;
  return m;
}

json campaign(const std::string& name, double time_scale) {
  return {{"name", name},
          {"program", "navigation"},
          {"rate_hz", 50},
          {"seed", 11},
          {"time_scale", time_scale},
          // Inline: a campaign names a truth of the daemon's truths folder or carries it, never a path.
          {"truth", json::parse(std::ifstream(imucaltest::source_dir() + "/examples/truth-nav-grade.json"))},
          {"model", start_model()},
          {"estimators", {"stage3"}}};
}

}  // namespace

TEST(CrashStage3, KillDashNineDuringStageThreeResumesToTheUninterruptedModel) {
  const std::string dir = scratch_dir("crash-stage3");
  const std::string log = dir + "/imucald.stderr";
  Daemon first = spawn(dir + "/data", log);
  ASSERT_GT(first.port, 0) << "imucald did not start; see " << log;
  const Client op{first.port, kOperatorToken};
  const auto id = op.post_and_start(campaign("killed during stage 3", 500));
  ASSERT_GT(id, 0);
  // Well into the program (8609 s): stage 3 has run for a while, and has a while to go.
  // (500x: the recorder commits every second of wall time, and the filter follows the commits.)
  const auto stage3_status = [](const json& c) {
    return c.value("estimators", json::object()).value("stage3", json::object()).value("status", "");
  };
  const json before = op.wait_for(id, [&](const json& c) {
    return c.at("program_time_s").get<double>() > 3000.0 && stage3_status(c) == "running";
  }, 600);
  ASSERT_EQ(before.at("state"), "running") << before.dump().substr(0, 1000);
  ASSERT_EQ(stage3_status(before), "running") << before.dump().substr(0, 3000);
  ::kill(first.pid, SIGKILL);
  EXPECT_EQ(wait_exit(first.pid, 10), 128 + SIGKILL);

  Daemon second = spawn(dir + "/data", log);
  ASSERT_GT(second.port, 0) << "imucald did not restart; see " << log;
  const Client op2{second.port, kOperatorToken};
  EXPECT_EQ(op2.get_json("/api/campaigns/" + std::to_string(id)).at("state"), "interrupted");
  ASSERT_EQ(op2.post("/api/campaigns/" + std::to_string(id) + "/resume").status, 200);
  const json resumed = op2.wait_state(id, "done", 900);
  ASSERT_EQ(resumed.at("state"), "done");
  EXPECT_TRUE(has_event(resumed, "redo", "resuming after an interruption"));

  // The same campaign, never interrupted.
  const auto id2 = op2.post_and_start(campaign("uninterrupted", 0));
  ASSERT_GT(id2, 0);
  const json whole = op2.wait_state(id2, "done", 900);
  ASSERT_EQ(whole.at("state"), "done");

  const json& a = resumed.at("results").at("stage3");
  const json& b = whole.at("results").at("stage3");
  ASSERT_EQ(a.at("status"), "done") << a.dump().substr(0, 1000);
  ASSERT_EQ(b.at("status"), "done") << b.dump().substr(0, 1000);
  EXPECT_EQ(a.at("frames"), b.at("frames"));
  // Every estimated coefficient within the uninterrupted run's 1 sigma.
  double worst = 0;
  int compared = 0;
  for (const auto& [name, pair] : b.at("estimates").items()) {
    const double sigma = pair.at(1).get<double>();
    if (!(sigma > 0)) continue;
    const double diff = a.at("estimates").at(name).at(0).get<double>() - pair.at(0).get<double>();
    worst = std::max(worst, std::abs(diff) / sigma);
    ++compared;
    EXPECT_LE(std::abs(diff), sigma) << name << ": resumed " << a.at("estimates").at(name).dump() << ", uninterrupted "
                                     << pair.dump();
  }
  EXPECT_GE(compared, 36);
  std::printf("stage 3 after kill -9 and resume: %d coefficients, worst difference %.3g sigma\n", compared, worst);
  ::kill(second.pid, SIGTERM);
  EXPECT_EQ(wait_exit(second.pid, 30), 0);
}
