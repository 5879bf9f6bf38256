// A full disk under imucald (issue 33): the run suspends with an operator's alarm, resumes by
// itself when space returns and ends `done` with every frame once; the API answers 503 to changes
// meanwhile; a run that fails while the disk is full fails cleanly (the daemon lives, the failure
// is stored once the disk takes it). The `full` program at the fastest time scale is in
// test_daemon_disk_full_long.cpp (slow).
#include <gtest/gtest.h>

#include "disk_full_fixture.hpp"

using namespace imucal;
using namespace imucal::daemontest;

TEST(DaemonDiskFull, ARunSuspendsOnAFullDiskAndEndsDoneWithEveryFrameOnceWhenSpaceReturns) {
  // A queue much shorter than the program: the disk fills with the producer mid-program (not with
  // the whole program already queued), so frames are refused and the redo must record them.
  LocalDaemon d("disk-full", false, [](daemon::DaemonConfig& c) {
    c.recorder.commit_interval_s = 0.05;
    c.recorder.queue_frames = 8192;
  });
  const json campaign = {{"name", "disk-full"}, {"program", "direct-short"}, {"rate_hz", 100}, {"seed", 7},
                         {"time_scale", 0},     {"truth", noisy_truth()},   {"estimators", {"direct"}}};
  const DiskFullRun r = run_with_a_full_disk(d, campaign, 1.5, 120);
  EXPECT_EQ(r.status_while_full, 200);
  EXPECT_EQ(r.refused_post, 503) << r.refused_post_body;
  EXPECT_NE(r.refused_post_body.find("disk is full"), std::string::npos) << r.refused_post_body;
  EXPECT_EQ(r.pause_while_full, 409) << r.pause_body;  // a suspended run cannot be paused
  EXPECT_NE(r.pause_body.find("it is suspended"), std::string::npos) << r.pause_body;
  ASSERT_EQ(r.campaign.at("state"), "done");
  EXPECT_EQ(r.campaign.at("results").at("direct").at("status"), "done");
  // Once space is back the API takes changes again.
  EXPECT_EQ(d.call("POST", "/api/campaigns", campaign.dump()).status, 201);
}

// A run that fails while the disk is full (here its start, through the test seam that fills the
// disk as the run file is opened): before issue 33 the failure's own write to the daemon database
// threw again and the process ended in std::terminate. Now every write is kept in memory and
// stored once the disk takes it; the daemon answers throughout.
TEST(DaemonDiskFull, ARunFailingWhileTheDiskIsFullFailsCleanlyAndIsStoredWhenSpaceReturns) {
  LocalDaemon d("disk-full-fail");
  DiskFullSwitch disk;
  daemon::Sequencer::RecorderHooks hooks;
  hooks.on_open = [&disk](storage::RunDb&, int) {
    disk.filled = true;
    storage::disk_fault::set_full(true);
    throw std::runtime_error("test: the bench broke while the disk was full");
  };
  d.service->sequencer().set_recorder_hooks(hooks);
  const auto id = d.post_campaign({{"name", "fails"}, {"program", "direct-short"}, {"rate_hz", 100},
                                   {"time_scale", 0}, {"estimators", json::array()}});
  ASSERT_EQ(d.command(id, "start"), 200);
  // The sequencer ends the run (no run in its telemetry) while nothing can be stored.
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(60);
  while (!(disk.filled.load() && d.service->sequencer().telemetry().at("run").is_null()) &&
         std::chrono::steady_clock::now() < deadline)
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
  ASSERT_TRUE(disk.filled.load());
  std::this_thread::sleep_for(std::chrono::milliseconds(700));  // the queue runner retries meanwhile
  EXPECT_EQ(d.call("GET", "/api/status").status, 200);
  EXPECT_EQ(d.campaign(id).at("state"), "running");  // the database's, behind the sequencer's
  EXPECT_EQ(d.call("POST", "/api/campaigns", json{{"name", "x"}, {"program", "direct-short"}}.dump()).status, 503);
  storage::disk_fault::set_full(false);

  const json c = d.wait_final(id, 60);
  ASSERT_EQ(c.at("state"), "failed") << c.dump().substr(0, 2000);
  EXPECT_NE(c.at("error").get<std::string>().find("the bench broke"), std::string::npos) << c.at("error");
  EXPECT_TRUE(has_transition(c, "running", "failed"));
  EXPECT_TRUE(has_event(c, "error", "the bench broke"));
  // The daemon goes on: the next campaign runs to the end.
  d.service->sequencer().set_recorder_hooks({});
  const auto next = d.post_campaign({{"name", "next"}, {"program", "direct-short"}, {"rate_hz", 100},
                                     {"time_scale", 0}, {"estimators", json::array()}});
  ASSERT_EQ(d.command(next, "start"), 200);
  EXPECT_EQ(d.wait_final(next, 120).at("state"), "done");
}

// imucald started on a full disk (issue 33): it starts (its schema already current, opening the
// database writes nothing), answers, refuses changes with a 503 that says why, and keeps what it
// must record meanwhile: its own audit entry for the start waits in memory, with the time it
// happened, and is chained into the trail once space returns.
TEST(DaemonDiskFull, ImucaldStartsOnAFullDiskAndItsAuditEntryIsStoredWhenSpaceReturns) {
  const daemon::DaemonConfig config = test_config(scratch_dir("disk-full-start"));
  {
    daemon::Service first(config);
    first.start(false);
    first.stop();
  }
  DiskFullSwitch disk;
  storage::disk_fault::set_full(true);
  const auto before_ms = daemon::now_unix_ms();
  std::unique_ptr<daemon::Service> service;
  ASSERT_NO_THROW(service = std::make_unique<daemon::Service>(config));
  service->start(false);
  auto call = [&](const std::string& method, const std::string& target, const std::string& body = "") {
    daemon::ApiRequest r;
    r.method = method;
    r.target = target;
    r.body = body;
    r.content_type = body.empty() ? "" : "application/json";
    r.authorization = std::string("Bearer ") + kOperatorToken;
    return service->api().handle(r);
  };
  EXPECT_EQ(call("GET", "/api/status").status, 200);
  const auto refused = call("POST", "/api/campaigns", json{{"name", "x"}, {"program", "direct-short"}}.dump());
  EXPECT_EQ(refused.status, 503) << refused.body;
  EXPECT_NE(refused.body.find("disk is full"), std::string::npos) << refused.body;
  auto started = [&] { return json::parse(call("GET", "/api/audit?action=service.started").body); };
  EXPECT_EQ(started().at("entries").size(), 1u) << "the second start's entry cannot be stored yet";

  // The stored entry's time must be before this: sleep so that "when it was stored" would differ.
  std::this_thread::sleep_for(std::chrono::milliseconds(20));
  const auto space_back_ms = daemon::now_unix_ms();
  std::this_thread::sleep_for(std::chrono::milliseconds(20));
  storage::disk_fault::set_full(false);
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(30);
  json audit = started();
  while (audit.at("entries").size() < 2 && std::chrono::steady_clock::now() < deadline) {
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
    audit = started();
  }
  ASSERT_EQ(audit.at("entries").size(), 2u) << audit.dump();
  EXPECT_TRUE(audit.at("intact").get<bool>()) << audit.dump();
  // Newest first: the second start, stamped when it happened (ISO 8601 orders as text), not when
  // it was stored.
  const std::string t = audit.at("entries").at(0).at("t").get<std::string>();
  EXPECT_GE(t, daemon::iso8601_utc(before_ms));
  EXPECT_LT(t, daemon::iso8601_utc(space_back_ms + 1));
  EXPECT_EQ(call("POST", "/api/campaigns", json{{"name", "x"}, {"program", "direct-short"}}.dump()).status, 201);
  service->stop();
}
