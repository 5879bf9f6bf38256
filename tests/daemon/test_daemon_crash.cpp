// The real imucald executable as a subprocess: kill -9 in the middle of a run, restart, and every
// frame committed before the kill is there exactly once; the run shows as interrupted, resumes
// from its last checkpoint after homing and completes, bit for bit the run an uninterrupted
// simulation gives. Then SIGTERM: a clean exit that parks the run. The same kill with sim-wire
// devices (real time, through the drivers): nothing committed lost or doubled, the grid complete.
#include <signal.h>

#include <cmath>
#include <fstream>

#include <gtest/gtest.h>

#include "service_fixture.hpp"
#include "subprocess.hpp"
#include "tests/test_paths.hpp"

using namespace imucal;
using namespace imucal::daemontest;

namespace {

using Daemon = DaemonProcess;
Daemon spawn(const std::string& data_dir, const std::string& log_path, const char* devices = "sim") {
  return spawn_imucald(imucaltest::program("imucald"), data_dir, log_path, kOperatorToken, devices);
}

}  // namespace

TEST(Crash, KillDashNineLosesNothingCommittedAndTheRunResumes) {
  const std::string dir = scratch_dir("crash");
  const std::string log = dir + "/imucald.stderr";
  Daemon first = spawn(dir + "/data", log);
  ASSERT_GT(first.port, 0) << "imucald did not start; see " << log;
  const Client op{first.port, kOperatorToken};
  const auto id = op.post_and_start(json{{"name", "crash"},
                                         {"program", "direct-short"},
                                         {"rate_hz", 100},
                                         {"seed", 3},
                                         {"time_scale", 50},
                                         {"truth", noisy_truth()},
                                         {"estimators", {"direct"}}});
  ASSERT_GT(id, 0);
  const json before = op.wait_for(id, [](const json& c) { return c.at("program_time_s").get<double>() > 150.0; });
  ASSERT_EQ(before.at("state"), "running");
  const std::string run_db = dir + "/data/" + before.at("run_db").get<std::string>();

  ::kill(first.pid, SIGKILL);
  EXPECT_EQ(wait_exit(first.pid, 10), 128 + SIGKILL);

  // What the crash left committed.
  const auto committed = run_frames(run_db);
  ASSERT_GT(committed.size(), 1000u);
  for (std::size_t i = 1; i < committed.size(); ++i) ASSERT_LT(committed[i - 1].t_ns, committed[i].t_ns);

  Daemon second = spawn(dir + "/data", log);
  ASSERT_GT(second.port, 0) << "imucald did not restart; see " << log;
  const Client op2{second.port, kOperatorToken};
  const json found = op2.get_json("/api/campaigns/" + std::to_string(id));
  EXPECT_EQ(found.at("state"), "interrupted");
  EXPECT_TRUE(has_transition(found, "running", "interrupted"));
  // Nothing was touched by the restart alone.
  const auto after_restart = run_frames(run_db);
  ASSERT_EQ(after_restart.size(), committed.size());

  const auto resume = op2.post("/api/campaigns/" + std::to_string(id) + "/resume");
  ASSERT_EQ(resume.status, 200) << resume.body;
  EXPECT_EQ(resume.json_body().at("state"), "queued");
  const json done = op2.wait_state(id, "done", 120);
  EXPECT_TRUE(has_event(done, "homed"));
  EXPECT_TRUE(has_event(done, "redo", "resuming after an interruption"));
  EXPECT_TRUE(done.at("has_model").get<bool>());

  const auto final_frames = run_frames(run_db);
  // Every committed frame is still there, once, unchanged.
  ASSERT_GE(final_frames.size(), committed.size());
  for (std::size_t i = 0; i < committed.size(); ++i) ASSERT_TRUE(same_frame(final_frames[i], committed[i])) << i;
  // And the whole run is what an uninterrupted simulation gives: no gap, no duplicate.
  expect_same_frames(final_frames, reference_frames(done.at("spec"), daemon::DaemonConfig{}));

  // SIGTERM mid-run: a clean exit, the run parked as interrupted with its frames committed.
  const auto again = op2.post("/api/campaigns", json{{"name", "term"}, {"program", "direct-short"}, {"time_scale", 50}}.dump());
  const auto id2 = again.json_body().at("id").get<std::int64_t>();
  ASSERT_EQ(op2.post("/api/campaigns/" + std::to_string(id2) + "/start").status, 200);
  const json running = op2.wait_for(id2, [](const json& c) { return c.at("program_time_s").get<double>() > 60.0; });
  ::kill(second.pid, SIGTERM);
  EXPECT_EQ(wait_exit(second.pid, 30), 0);
  Daemon third = spawn(dir + "/data", log);
  ASSERT_GT(third.port, 0);
  const Client op3{third.port, kOperatorToken};
  const json parked = op3.get_json("/api/campaigns/" + std::to_string(id2));
  EXPECT_EQ(parked.at("state"), "interrupted");
  bool clean = false;
  for (const auto& t : parked.at("transitions"))
    clean = clean || t.at("reason").get<std::string>().find("the daemon shut down") != std::string::npos;
  EXPECT_TRUE(clean) << parked.dump();
  EXPECT_EQ(parked.at("frames").get<std::int64_t>(),
            static_cast<std::int64_t>(run_frames(dir + "/data/" + running.at("run_db").get<std::string>()).size()));
  ::kill(third.pid, SIGTERM);
  EXPECT_EQ(wait_exit(third.pid, 30), 0);
}

// sim-wire: the simulated devices die with the daemon; after the restart the run resumes on a new
// set through the drivers. Frames are not reproducible in real time, so the check is that every
// frame committed before the kill is still there unchanged and the file ends up holding every
// instant of the program's grid exactly once.
TEST(Crash, SimWireKillDashNineLosesNothingCommittedAndTheRunResumes) {
  const std::string dir = scratch_dir("crash-wire");
  const std::string log = dir + "/imucald.stderr";
  Daemon first = spawn(dir + "/data", log, "sim-wire");
  ASSERT_GT(first.port, 0) << "imucald did not start; see " << log;
  const Client op{first.port, kOperatorToken};
  const json program = json::parse(R"({"name": "wire-crash", "segments": [
    {"type": "hold", "name": "start", "duration_s": 2},
    {"type": "move", "name": "tilt", "to_deg": [0, 90, 0], "duration_s": 2},
    {"type": "rate", "name": "spin", "axis": "outer", "rate_dps": 20, "duration_s": 4, "accel_dps2": 40},
    {"type": "hold", "name": "end", "duration_s": 2}]})");
  const auto id = op.post_and_start(json{{"name", "crash-wire"}, {"program", program}, {"rate_hz", 100},
                                         {"estimators", json::array()}});
  ASSERT_GT(id, 0);
  // In the spin, more than a commit interval after the last segment boundary.
  const json before = op.wait_for(id, [](const json& c) { return c.at("program_time_s").get<double>() > 6.5; }, 60);
  ASSERT_EQ(before.at("state"), "running") << before.dump();
  const std::string run_db = dir + "/data/" + before.at("run_db").get<std::string>();

  ::kill(first.pid, SIGKILL);
  EXPECT_EQ(wait_exit(first.pid, 10), 128 + SIGKILL);
  const auto committed = run_frames(run_db);
  ASSERT_GT(committed.size(), 400u);
  for (std::size_t i = 1; i < committed.size(); ++i) ASSERT_EQ(committed[i].t_ns - committed[i - 1].t_ns, 10'000'000);

  Daemon second = spawn(dir + "/data", log, "sim-wire");
  ASSERT_GT(second.port, 0) << "imucald did not restart; see " << log;
  const Client op2{second.port, kOperatorToken};
  EXPECT_EQ(op2.get_json("/api/campaigns/" + std::to_string(id)).at("state"), "interrupted");
  const auto resume = op2.post("/api/campaigns/" + std::to_string(id) + "/resume");
  ASSERT_EQ(resume.status, 200) << resume.body;
  const json done = op2.wait_for(id, [](const json& c) {
    const auto s = c.value("state", "");
    return s == "done" || s == "failed" || s == "aborted";
  }, 90);
  ASSERT_EQ(done.at("state"), "done") << done.dump();
  EXPECT_TRUE(has_event(done, "homed"));
  EXPECT_TRUE(has_event(done, "redo", "resuming after an interruption"));

  const auto final_frames = run_frames(run_db);
  ASSERT_GE(final_frames.size(), committed.size());
  for (std::size_t i = 0; i < committed.size(); ++i) ASSERT_TRUE(same_frame(final_frames[i], committed[i])) << i;
  EXPECT_EQ(final_frames.size(), 1000u);
  std::size_t off_grid = final_frames.front().t_ns != 10'000'000;
  for (std::size_t i = 1; i < final_frames.size(); ++i)
    off_grid += final_frames[i].t_ns - final_frames[i - 1].t_ns != 10'000'000;
  EXPECT_EQ(off_grid, 0u);
  EXPECT_EQ(done.at("frames").get<std::int64_t>(), static_cast<std::int64_t>(final_frames.size()));

  ::kill(second.pid, SIGTERM);
  EXPECT_EQ(wait_exit(second.pid, 30), 0);
}

// A sim_fault fires once, on the first pass. A run resumed after a kill starts a new simulated
// bench; before issue 33 every fault at or before the resume point fired again at once on its
// first frame (a second suspension for a fault long over), and the resumed run counted its lost
// frames from zero. Now the faults up to the last committed frame count as passed, and the
// counters go on from what was stored.
TEST(Crash, AResumedRunDoesNotFireAgainTheFaultsItPassedAndKeepsItsCounts) {
  const std::string dir = scratch_dir("crash-faults");
  const std::string log = dir + "/imucald.stderr";
  Daemon first = spawn(dir + "/data", log);
  ASSERT_GT(first.port, 0) << "imucald did not start; see " << log;
  const Client op{first.port, kOperatorToken};
  json campaign = {{"name", "faults then kill"}, {"program", "direct-short"}, {"rate_hz", 100}, {"seed", 5},
                   {"time_scale", 50},           {"estimators", json::array()},
                   {"suspenders", {{"settle_s", 2}}}};
  campaign["sim_faults"] = {{{"kind", "imu_drop"}, {"at_s", 100}, {"frames", 7}}};
  const auto id = op.post_and_start(campaign);
  ASSERT_GT(id, 0);
  const json before = op.wait_for(id, [](const json& c) {
    return has_event(c, "resumed") && c.at("program_time_s").get<double>() > 250.0;
  }, 120);
  ASSERT_EQ(before.at("state"), "running") << before.dump().substr(0, 2000);
  EXPECT_EQ(before.at("lost_frames"), 7);
  ::kill(first.pid, SIGKILL);
  EXPECT_EQ(wait_exit(first.pid, 10), 128 + SIGKILL);

  Daemon second = spawn(dir + "/data", log);
  ASSERT_GT(second.port, 0) << "imucald did not restart; see " << log;
  const Client op2{second.port, kOperatorToken};
  ASSERT_EQ(op2.post("/api/campaigns/" + std::to_string(id) + "/resume").status, 200);
  const json done = op2.wait_state(id, "done", 120);
  ASSERT_EQ(done.at("state"), "done") << done.dump().substr(0, 2000);
  EXPECT_TRUE(has_event(done, "redo", "resuming after an interruption"));
  int suspensions = 0;
  for (const auto& e : done.at("events")) suspensions += e.at("kind") == "suspended";
  EXPECT_EQ(suspensions, 1) << done.at("events").dump().substr(0, 3000);
  EXPECT_EQ(done.at("lost_frames"), 7);
  ::kill(second.pid, SIGTERM);
  EXPECT_EQ(wait_exit(second.pid, 30), 0);
}

// kill -9 during the soak at 15 C of thermal-short on the simulated bench with its thermal model:
// the restarted bench's chamber stood at the profile's start (25 C) until the program was under
// way again, so the resumed run waited for a chamber that could never come into the 15 C band and
// failed after an hour of device time ("the chamber did not reach its set point within 3600 s";
// found by the chaos soak). Now it stands where the run was.
TEST(Crash, AThermalRunResumedInItsColdSoakFindsTheChamberWhereItWas) {
  const std::string dir = scratch_dir("crash-thermal");
  const std::string log = dir + "/imucald.stderr";
  Daemon first = spawn(dir + "/data", log);
  ASSERT_GT(first.port, 0) << "imucald did not start; see " << log;
  const Client op{first.port, kOperatorToken};
  const json campaign = {{"name", "cold soak, kill"}, {"program", "thermal-short"}, {"rate_hz", 20},
                         {"time_scale", 400},
                         {"truth", json::parse(std::ifstream(imucaltest::source_dir() + "/examples/truth-thermal.json"))}};
  const auto id = op.post_and_start(campaign);
  ASSERT_GT(id, 0);
  // The soak at 15 C is 1200..3000 s of program.
  const json before = op.wait_for(id, [](const json& c) { return c.at("program_time_s").get<double>() > 1500.0; }, 120);
  ASSERT_EQ(before.at("state"), "running") << before.dump().substr(0, 2000);
  ::kill(first.pid, SIGKILL);
  EXPECT_EQ(wait_exit(first.pid, 10), 128 + SIGKILL);

  Daemon second = spawn(dir + "/data", log);
  ASSERT_GT(second.port, 0) << "imucald did not restart; see " << log;
  const Client op2{second.port, kOperatorToken};
  ASSERT_EQ(op2.post("/api/campaigns/" + std::to_string(id) + "/resume").status, 200);
  const json done = op2.wait_for(id, [](const json& c) {
    const auto s = c.value("state", "");
    return s == "done" || s == "failed" || s == "aborted";
  }, 180);
  ASSERT_EQ(done.at("state"), "done") << done.dump().substr(0, 3000);
  EXPECT_TRUE(has_event(done, "redo", "resuming after an interruption"));
  const auto frames = run_frames(dir + "/data/" + done.at("run_db").get<std::string>());
  EXPECT_EQ(static_cast<double>(frames.size()), std::round(done.at("duration_s").get<double>() * 20.0));
  ::kill(second.pid, SIGTERM);
  EXPECT_EQ(wait_exit(second.pid, 30), 0);
}
