// The sequencer in-process on the simulated bench: whole runs, pause and resume, every suspender
// (safe hold, automatic resume, the segment redone, the interruption in the run record), stop,
// abort, the queue, commands in the wrong state. A run's frames are compared bit for bit with the
// same program simulated straight through: nothing lost, nothing twice, whatever happened.
#include <gtest/gtest.h>

#include <atomic>
#include <fstream>
#include <limits>
#include <memory>

#include "daemon/campaign_runner.hpp"
#include "service_fixture.hpp"

using namespace imucal;
using namespace imucal::daemontest;

namespace {

json short_campaign(const std::string& name, double time_scale) {
  return {{"name", name},      {"program", "direct-short"}, {"rate_hz", 100},
          {"seed", 7},         {"time_scale", time_scale},  {"truth", noisy_truth()},
          {"estimators", {"direct", "navigation"}}};
}

}  // namespace

TEST(Sequencer, RunsACampaignToTheEndWithItsModel) {
  LocalDaemon d("run");
  const auto id = d.post_campaign(short_campaign("whole", 0));
  EXPECT_EQ(d.campaign(id).at("state"), "created");
  ASSERT_EQ(d.command(id, "start"), 200);
  const json c = d.wait_final(id);
  ASSERT_EQ(c.at("state"), "done") << c.dump();
  EXPECT_TRUE(has_transition(c, "created", "queued"));
  EXPECT_TRUE(has_transition(c, "queued", "running"));
  EXPECT_TRUE(has_transition(c, "running", "done"));
  EXPECT_TRUE(c.at("has_model").get<bool>());
  EXPECT_EQ(c.at("results").at("direct").at("status"), "done");
  EXPECT_EQ(c.at("results").at("navigation").at("status"), "done");
  EXPECT_EQ(c.at("lost_frames"), 0);

  const auto model = d.call("GET", "/api/campaigns/" + std::to_string(id) + "/model");
  ASSERT_EQ(model.status, 200);
  const ImuModel m = imu_model_from_json_text(model.body, "model");
  EXPECT_TRUE(m.sigma.has_value());
  // The bias the truth has, within the short program's accuracy.
  EXPECT_NEAR(m.accel.bias_mps2.y(), 2e-4, 5e-5);
  EXPECT_EQ(d.call("GET", "/api/campaigns/" + std::to_string(id) + "/model?frame=body").status, 200);

  const auto frames = run_frames(d.run_path(c));
  expect_same_frames(frames, reference_frames(c.at("spec"), d.config));
  EXPECT_EQ(c.at("frames"), static_cast<std::int64_t>(frames.size()));

  // Every exit leaves the table stopped with its interlock open, the chamber at its safe set point.
  const json t = d.service->sequencer().telemetry();
  EXPECT_FALSE(t.at("table").at("interlock_closed").get<bool>());
  EXPECT_EQ(t.at("table").at("rate_dps"), json::array({0.0, 0.0, 0.0}));
  EXPECT_DOUBLE_EQ(t.at("chamber").at("setpoint_C").get<double>(), d.config.chamber.safe_setpoint_C);

  // Estimator progress was stored along the way.
  const json progress = d.get("/api/campaigns/" + std::to_string(id) + "/progress");
  ASSERT_TRUE(progress.contains("direct"));
  EXPECT_GE(progress.at("direct").size(), 1u);
}

TEST(Sequencer, PauseAndResumeRedoTheSegmentWithoutDuplicates) {
  LocalDaemon d("pause");
  const auto id = d.post_campaign(short_campaign("paused", 100));
  ASSERT_EQ(d.command(id, "start"), 200);
  d.wait_for(id, [](const json& c) { return c.at("program_time_s").get<double>() > 60.0; });
  ASSERT_EQ(d.command(id, "pause"), 200);
  EXPECT_EQ(d.command(id, "pause"), 409);  // pausing already
  const json paused = d.wait_state(id, "paused");
  EXPECT_TRUE(has_transition(paused, "running", "pausing"));
  EXPECT_TRUE(has_transition(paused, "pausing", "paused"));
  const double held_s = paused.at("program_time_s").get<double>();
  std::this_thread::sleep_for(std::chrono::milliseconds(300));
  EXPECT_DOUBLE_EQ(d.campaign(id).at("program_time_s").get<double>(), held_s);  // nothing moves
  const json t = d.service->sequencer().telemetry();
  EXPECT_EQ(t.at("table").at("rate_dps"), json::array({0.0, 0.0, 0.0}));
  EXPECT_EQ(t.at("run").at("state"), "paused");
  EXPECT_FALSE(t.at("table").at("interlock_closed").get<bool>());  // safe hold: the interlock is open
  ASSERT_EQ(d.command(id, "resume"), 200);
  EXPECT_EQ(d.command(id, "resume"), 409);  // resume while running
  const json c = d.wait_final(id);
  ASSERT_EQ(c.at("state"), "done");
  EXPECT_TRUE(has_transition(c, "paused", "running"));
  EXPECT_TRUE(has_event(c, "paused"));
  EXPECT_TRUE(has_event(c, "resumed", "redoing segment"));
  expect_same_frames(run_frames(d.run_path(c)), reference_frames(c.at("spec"), d.config));
}

namespace {

constexpr std::size_t kNoSegment = std::numeric_limits<std::size_t>::max();

// The telemetry of a prompt for another segment than `answered` (the one answered last may still
// show until the run publishes again; kNoSegment: any). No std::optional here: clang-tidy 16's
// optional-access analysis of the test below ran past the static check's 600 s with one.
json wait_prompt(LocalDaemon& d, std::size_t answered) {
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(120);
  while (std::chrono::steady_clock::now() < deadline) {
    const json t = d.service->sequencer().telemetry();
    if (t.contains("run") && t.at("run").is_object() && t.at("run").value("prompt", json(nullptr)).is_object() &&
        t.at("run").at("prompt").at("segment").get<std::size_t>() != answered)
      return t;
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
  }
  ADD_FAILURE() << "no prompt";
  return json();
}

}  // namespace

// The repeatability program's power cycles: before each the run holds the table safe, asks the
// operator (telemetry run.prompt, an event) and waits; an answer through the API continues it; a
// pause while it waits asks again after the resume; the run file holds every instant once.
TEST(Sequencer, APowerCycleWaitsForTheOperatorsAnswer) {
  LocalDaemon d("power-cycle");
  json truth = noisy_truth();
  truth["turn_on"] = {{"gyro", {{"bias_repeatability_dph", {0.02, 0.01, 0.03}}}},
                      {"accel", {{"bias_repeatability_mps2", {1e-4, 2e-4, 1.5e-4}}}}};
  const auto id = d.post_campaign({{"name", "repeatability"}, {"program", "repeatability-short"}, {"rate_hz", 10},
                                   {"time_scale", 0}, {"truth", truth}});
  EXPECT_EQ(d.campaign(id).at("spec").at("estimators"), json({"repeatability"}));
  const std::string prompt_url = "/api/campaigns/" + std::to_string(id) + "/prompt";
  EXPECT_EQ(d.call("POST", prompt_url, R"({"answer": "done"})").status, 409) << "nothing is asked before the start";
  ASSERT_EQ(d.command(id, "start"), 200);
  std::size_t answered = kNoSegment;
  for (int cycle = 2; cycle <= 6; ++cycle) {
    const json t = wait_prompt(d, answered);
    ASSERT_TRUE(t.is_object());
    EXPECT_EQ(t.at("run").at("state"), "running");
    EXPECT_NE(t.at("run").at("prompt").at("text").get<std::string>().find("Power-cycle the IMU"), std::string::npos);
    EXPECT_EQ(t.at("table").at("rate_dps"), json::array({0.0, 0.0, 0.0}));
    EXPECT_FALSE(t.at("table").at("interlock_closed").get<bool>()) << "the operator may reach the IMU";
    // The run's own program time (its telemetry), not the campaign row's stored progress, which
    // is written a moment later and under load was still the earlier value (310 s, then 470 s).
    const double held_s = t.at("run").at("program_time_s").get<double>();
    std::this_thread::sleep_for(std::chrono::milliseconds(200));
    EXPECT_DOUBLE_EQ(d.service->sequencer().telemetry().at("run").at("program_time_s").get<double>(), held_s)
        << "it waits";
    if (cycle == 3) {
      // Paused while it asks: after the resume it asks again.
      ASSERT_EQ(d.command(id, "pause"), 200);
      d.wait_state(id, "paused");
      EXPECT_TRUE(d.service->sequencer().telemetry().at("run").at("prompt").is_null());
      ASSERT_EQ(d.command(id, "resume"), 200);
      ASSERT_TRUE(wait_prompt(d, kNoSegment).is_object());
    }
    const auto wrong = d.call("POST", prompt_url, R"({"answer": "later"})");
    EXPECT_EQ(wrong.status, 400);
    EXPECT_NE(wrong.body.find("body.answer must be"), std::string::npos) << wrong.body;
    EXPECT_EQ(d.call("POST", prompt_url, R"({"answer": "done"})", kViewerToken).status, 403);
    ASSERT_EQ(d.call("POST", prompt_url, R"({"answer": "done"})").status, 200);
    answered = t.at("run").at("prompt").at("segment").get<std::size_t>();
  }
  const json c = d.wait_final(id);
  ASSERT_EQ(c.at("state"), "done");
  int asked = 0, answers = 0;
  for (const auto& e : c.at("events")) {
    asked += e.at("kind") == "prompt";
    answers += e.at("kind") == "prompt-answered";
  }
  EXPECT_EQ(asked, 6) << "five power cycles, one asked twice (the pause)";
  EXPECT_EQ(answers, 5);
  EXPECT_TRUE(has_event(c, "prompt-answered", "answered by operator"));
  const json& r = c.at("results").at("repeatability");
  ASSERT_EQ(r.at("status"), "done") << r.dump();
  EXPECT_EQ(r.at("repeatability").at("turn_ons").size(), 6u);
  expect_same_frames(run_frames(d.run_path(c)), reference_frames(c.at("spec"), d.config));
}

TEST(Sequencer, SuspendsWhenTheChamberLeavesItsBandAndResumesByItself) {
  LocalDaemon d("chamber");
  json campaign = short_campaign("chamber", 0);
  campaign["sim_faults"] = {{{"kind", "chamber_offset"}, {"at_s", 150}, {"duration_s", 20}, {"offset_C", 6}}};
  const auto id = d.post_campaign(campaign);
  ASSERT_EQ(d.command(id, "start"), 200);
  const json c = d.wait_final(id);
  ASSERT_EQ(c.at("state"), "done") << c.dump();
  EXPECT_TRUE(has_transition(c, "running", "suspended"));
  EXPECT_TRUE(has_transition(c, "suspended", "running"));
  EXPECT_TRUE(has_event(c, "suspended", "chamber out of band"));
  EXPECT_TRUE(has_event(c, "resumed", "redoing segment"));
  expect_same_frames(run_frames(d.run_path(c)), reference_frames(c.at("spec"), d.config));
  // The interruption is in the run file itself too.
  const auto db = storage::RunDb::open(d.run_path(c), storage::OpenMode::Read);
  const auto record = db.extra("imucald_run");
  ASSERT_TRUE(record.has_value());
  EXPECT_NE(record->find("chamber out of band"), std::string::npos);
  EXPECT_NE(record->find("\"suspended\""), std::string::npos);
}

TEST(Sequencer, EverySuspenderHoldsAndResumes) {
  LocalDaemon d("faults");
  json campaign = short_campaign("faults", 0);
  campaign["sim_faults"] = {
      {{"kind", "imu_dropout"}, {"at_s", 40}, {"duration_s", 3}},
      {{"kind", "imu_corrupt"}, {"at_s", 90}, {"frames", 3}},
      {{"kind", "disconnect"}, {"device", "imu"}, {"at_s", 140}, {"duration_s", 2}},
      {{"kind", "disconnect"}, {"device", "table"}, {"at_s", 190}, {"duration_s", 2}},
      {{"kind", "table_fault"}, {"at_s", 240}, {"duration_s", 2}},
      {{"kind", "disconnect"}, {"device", "chamber"}, {"at_s", 290}, {"duration_s", 2}},
  };
  const auto id = d.post_campaign(campaign);
  ASSERT_EQ(d.command(id, "start"), 200);
  const json c = d.wait_final(id);
  ASSERT_EQ(c.at("state"), "done") << c.dump();
  EXPECT_TRUE(has_event(c, "suspended", "IMU frames missing") || has_event(c, "suspended", "frame(s) missing"));
  EXPECT_TRUE(has_event(c, "suspended", "corrupt IMU frame"));
  EXPECT_TRUE(has_event(c, "suspended", "IMU: IMU does not answer"));
  EXPECT_TRUE(has_event(c, "suspended", "table disconnected"));
  EXPECT_TRUE(has_event(c, "suspended", "table fault"));
  EXPECT_TRUE(has_event(c, "suspended", "chamber disconnected"));
  int resumed = 0;
  for (const auto& e : c.at("events")) resumed += e.at("kind") == "resumed";
  EXPECT_GE(resumed, 6);
  EXPECT_GT(c.at("lost_frames").get<std::int64_t>(), 0);
  EXPECT_GT(c.at("bad_frames").get<std::int64_t>(), 0);
  // Suspended data was never recorded twice, and what was missing was recorded on the redo.
  expect_same_frames(run_frames(d.run_path(c)), reference_frames(c.at("spec"), d.config));
}

// Issue 8's backpressure: a writer that stalls (a slow disk) under a device that cannot wait. The
// queue passes its high-water level, the alarm is an event of the run, the run suspends before any
// frame is dropped, the recorder drains, and the run resumes: the file holds every frame once.
TEST(Sequencer, RecorderFallingBehindSuspendsTheRunBeforeAFrameIsLost) {
  LocalDaemon d("behind", false, [](daemon::DaemonConfig& c) {
    c.recorder.queue_frames = 8192;
    c.recorder.commit_interval_s = 0.05;
  });
  auto commits = std::make_shared<std::atomic<int>>(0);
  daemon::Sequencer::RecorderHooks hooks;
  hooks.wait_when_full = false;  // as with real devices: a full queue would drop
  hooks.after_commit = [commits](const storage::RecorderStats&) {
    if (++*commits == 5) std::this_thread::sleep_for(std::chrono::milliseconds(1500));  // the disk stalls
  };
  d.service->sequencer().set_recorder_hooks(hooks);
  // 100 Hz at 100x: 10,000 frames a second, so the stall fills 6144 of 8192 in about 0.6 s.
  const auto id = d.post_campaign(short_campaign("behind", 100));
  ASSERT_EQ(d.command(id, "start"), 200);
  const json c = d.wait_final(id);
  ASSERT_EQ(c.at("state"), "done") << c.dump();
  EXPECT_TRUE(has_event(c, "alarm", "queue_high_water"));
  EXPECT_TRUE(has_event(c, "suspended", "the recorder falls behind"));
  EXPECT_TRUE(has_transition(c, "suspended", "running"));
  EXPECT_EQ(c.at("lost_frames"), 0);
  expect_same_frames(run_frames(d.run_path(c)), reference_frames(c.at("spec"), d.config));
  // The high-water mark is counted in the run file, and the alarm is in its record.
  const auto db = storage::RunDb::open(d.run_path(c), storage::OpenMode::Read);
  std::int64_t high_water = 0;
  for (const auto& session : db.sessions()) high_water = std::max(high_water, session.queue_high_water_frames);
  EXPECT_GE(high_water, 6144);
  EXPECT_TRUE(db.dropped_spans().empty());
  const auto record = db.extra("imucald_run");
  ASSERT_TRUE(record.has_value());
  EXPECT_NE(record->find("queue_high_water"), std::string::npos);
}

// A full disk under a run: test_daemon_disk_full.cpp.

TEST(Sequencer, StopAndAbortEndEarlyWithPartialResults) {
  LocalDaemon d("stop");
  json campaign = short_campaign("stop", 100);
  const auto stop_id = d.post_campaign(campaign);
  const auto abort_id = d.post_campaign(campaign);
  ASSERT_EQ(d.command(stop_id, "start"), 200);
  ASSERT_EQ(d.command(abort_id, "start"), 200);
  // The second waits in the queue while the first runs.
  d.wait_state(stop_id, "running");
  const json queued = d.campaign(abort_id);
  EXPECT_EQ(queued.at("state"), "queued");
  EXPECT_EQ(queued.at("queue_position"), 0);
  d.wait_for(stop_id, [](const json& c) { return c.at("program_time_s").get<double>() > 30.0; });
  ASSERT_EQ(d.command(stop_id, "stop"), 200);
  const json stopped = d.wait_final(stop_id);
  EXPECT_EQ(stopped.at("state"), "done");
  EXPECT_TRUE(has_transition(stopped, "running", "stopping"));
  EXPECT_TRUE(has_transition(stopped, "stopping", "done"));
  EXPECT_LT(stopped.at("program_time_s").get<double>(), stopped.at("duration_s").get<double>());
  EXPECT_TRUE(stopped.at("results").contains("direct"));  // a result or the reason there is none

  d.wait_for(abort_id, [](const json& c) { return c.at("program_time_s").get<double>() > 10.0; });
  ASSERT_EQ(d.command(abort_id, "abort"), 200);
  const json aborted = d.wait_final(abort_id);
  EXPECT_EQ(aborted.at("state"), "aborted");
  EXPECT_TRUE(has_transition(aborted, "running", "aborting"));
  // An aborted run is partial: the estimators finished on the data so far, after the table was
  // parked (a result or the reason there is none), and it is no calibration of its unit.
  EXPECT_FALSE(aborted.at("complete").get<bool>());
  EXPECT_TRUE(aborted.at("results").contains("direct")) << aborted.at("results").dump();
  EXPECT_EQ(d.call("GET", "/api/campaigns/" + std::to_string(abort_id) + "/model").status,
            aborted.at("has_model").get<bool>() ? 200 : 404);
  const json t = d.service->sequencer().telemetry();
  EXPECT_FALSE(t.at("table").at("interlock_closed").get<bool>());
  // The frames recorded before the abort are kept, each once.
  const auto frames = run_frames(d.run_path(aborted));
  const auto want = reference_frames(aborted.at("spec"), d.config);
  ASSERT_LE(frames.size(), want.size());
  ASSERT_GT(frames.size(), 0u);
  for (std::size_t i = 0; i < frames.size(); ++i) ASSERT_TRUE(same_frame(frames[i], want[i])) << i;
}

TEST(Sequencer, CommandsInTheWrongStateChangeNothing) {
  LocalDaemon d("wrong-state");
  const auto id = d.post_campaign(short_campaign("x", 0));
  EXPECT_EQ(d.command(id, "pause"), 409);
  EXPECT_EQ(d.command(id, "resume"), 409);
  EXPECT_EQ(d.command(id, "stop"), 409);
  EXPECT_EQ(d.campaign(id).at("state"), "created");
  ASSERT_EQ(d.command(id, "start"), 200);
  const auto twice = d.call("POST", "/api/campaigns/" + std::to_string(id) + "/start");
  EXPECT_EQ(twice.status, 409);
  EXPECT_NE(twice.body.find("already started"), std::string::npos) << twice.body;
  ASSERT_EQ(d.wait_final(id).at("state"), "done");
  EXPECT_EQ(d.command(id, "start"), 409);
  EXPECT_EQ(d.command(id, "abort"), 409);
  EXPECT_EQ(d.command(id + 100, "start"), 404);
  // A created campaign can be aborted without ever moving.
  const auto never = d.post_campaign(short_campaign("never", 0));
  EXPECT_EQ(d.command(never, "abort"), 200);
  EXPECT_EQ(d.campaign(never).at("state"), "aborted");
}

TEST(Sequencer, ShutdownParksTheRunAsInterruptedAndItResumes) {
  const std::string dir = scratch_dir("shutdown");
  json spec_json;
  std::int64_t id = 0;
  std::size_t frames_before = 0;
  daemon::DaemonConfig config = test_config(dir);
  {
    daemon::Service service(config);
    service.start(false);
    daemon::ApiRequest post{"POST", "/api/campaigns", std::string("Bearer ") + kOperatorToken, "", "application/json",
                            short_campaign("parked", 100).dump(), "", "", ""};
    id = json::parse(service.api().handle(post).body).at("id").get<std::int64_t>();
    ASSERT_EQ(service.sequencer().command(id, daemon::Command::Start, "test", "").http_status, 200);
    const auto program_time_s = [&] {
      const auto r = service.db().campaign(id);
      return r ? r->program_time_s : 0.0;
    };
    for (int i = 0; i < 2000 && program_time_s() < 50.0; ++i) std::this_thread::sleep_for(std::chrono::milliseconds(5));
    service.stop();  // what SIGTERM does
    const auto row = service.db().campaign(id);
    ASSERT_TRUE(row);
    EXPECT_EQ(row->state, daemon::RunState::Interrupted);
    spec_json = json::parse(row->spec_json);
    frames_before = run_frames(dir + "/" + row->run_db).size();
    EXPECT_EQ(static_cast<std::int64_t>(frames_before), row->frames);  // the recorder was flushed
  }
  daemon::Service again(config);
  again.start(false);
  ASSERT_EQ(again.sequencer().command(id, daemon::Command::Resume, "test", "").http_status, 200);
  const auto ended = [&] {
    const auto r = again.db().campaign(id);
    return r && daemon::is_final(r->state);
  };
  for (int i = 0; i < 30000 && !ended(); ++i) std::this_thread::sleep_for(std::chrono::milliseconds(5));
  const auto row = again.db().campaign(id);
  ASSERT_TRUE(row);
  ASSERT_EQ(row->state, daemon::RunState::Done);
  again.stop();
  expect_same_frames(run_frames(dir + "/" + row->run_db), reference_frames(spec_json, config));
}

TEST(CampaignRun, RunsAFileInProcessAndWritesTheModel) {
  const std::string dir = scratch_dir("campaign-run");
  const std::string file = dir + "/campaign.json";
  std::ofstream(file) << R"({"_comment": "regression run", "name": "cli", "program": "direct-short", "rate_hz": 100,
                             "estimators": ["direct", "navigation"]})";
  daemon::CampaignRunOptions options;
  options.data_dir = dir + "/data";
  options.model_out = dir + "/model.json";
  options.progress = false;
  const auto r = daemon::run_campaign_file(file, options);
  EXPECT_EQ(r.exit_code, 0) << r.error;
  EXPECT_EQ(r.state, "done");
  EXPECT_EQ(r.frames, 40260);
  EXPECT_GT(r.wall_s, 0.0);  // the speed figure is a benchmark (bench/README.md)
  EXPECT_EQ(r.results.at("navigation").at("status"), "done");
  EXPECT_NO_THROW(read_imu_model_file(options.model_out));

  std::ofstream(dir + "/bad.json") << R"({"name": "bad", "program": "direct", "rate_hz": 1e6, "estimators": ["x"]})";
  const auto bad = daemon::run_campaign_file(dir + "/bad.json", options);
  EXPECT_EQ(bad.exit_code, 2);
  EXPECT_NE(bad.error.find("rate_hz"), std::string::npos) << bad.error;
  EXPECT_NE(bad.error.find("unknown estimator"), std::string::npos) << bad.error;
}
