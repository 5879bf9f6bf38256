// The recording bundle (GET /api/campaigns/{id}/recording, issue 33): written by a job like the
// analyses, never on the HTTP thread, counted against the same bound of jobs; and the intervals a
// fault held the run listed in its meta.json, which `imucal import` reads back.
#include <algorithm>
#include <cstdlib>
#include <filesystem>
#include <fstream>

#include <gtest/gtest.h>

#include "daemon/subscribers/faulted_intervals.hpp"
#include "service_fixture.hpp"
#include "storage/bundle.hpp"
#include "storage/run_db.hpp"
#include "tests/test_paths.hpp"

using namespace imucal;
using namespace imucal::daemontest;
using daemon::EventRow;
using daemon::RunState;
using daemon::TransitionRow;

namespace {

std::string time_text(std::int64_t t_ms) { return daemon::iso8601_utc(t_ms); }

// A command line's exit status (the test's own `tar` and `imucal` runs).
int shell(const std::string& command) { return std::system(command.c_str()); }

}  // namespace

// From a run's history: each suspension and each interruption, with its reason, its span in wall
// time and where it lies in program time; a pause (the operator's) is not a fault.
TEST(FaultedIntervals, EachSuspensionAndInterruptionWithItsReasonAndPlace) {
  const std::vector<TransitionRow> history = {
      {1'000, std::nullopt, RunState::Created, "posted"},
      {2'000, RunState::Created, RunState::Queued, "start by alice"},
      {3'000, RunState::Queued, RunState::Running, "devices free"},
      {4'000, RunState::Running, RunState::Suspended, "chamber out of band: 36.1 °C"},
      {9'000, RunState::Suspended, RunState::Running, "chamber out of band: 36.1 °C cleared"},
      {10'000, RunState::Running, RunState::Pausing, "pause by alice"},
      {11'000, RunState::Pausing, RunState::Paused, "table stopped, recording committed"},
      {12'000, RunState::Paused, RunState::Running, "resume by alice"},
      {13'000, RunState::Running, RunState::Suspended, "no IMU frame for 1 s"},
      // Killed while suspended: found at start-up, resumed by an operator, queued, running again.
      {20'000, RunState::Suspended, RunState::Interrupted, "found active at start-up: crash or power loss"},
      {21'000, RunState::Interrupted, RunState::Queued, "resume by bob"},
      {22'000, RunState::Queued, RunState::Running, "devices free"},
      {30'000, RunState::Running, RunState::Done, "program complete"}};
  const std::vector<EventRow> events = {
      {4'000, "suspended", 3, 150.25, "chamber out of band: 36.1 °C"},
      {9'000, "resumed", 3, 150.25, "condition cleared"},
      {10'500, "paused", 4, 200.0, "paused in segment 4"},
      {13'001, "suspended", 5, 300.5, "no IMU frame for 1 s"},
      {22'001, "info", 0, 0.0, "bench"},
      {22'002, "redo", 5, 290.0, "resuming after an interruption: ... committed up to 290 s"}};
  const json intervals = daemon::faulted_intervals(history, events);
  const json want = {
      {{"state", "suspended"}, {"reason", "chamber out of band: 36.1 °C"}, {"start", time_text(4'000)},
       {"end", time_text(9'000)}, {"program_time_s", 150.25}},
      {{"state", "suspended"}, {"reason", "no IMU frame for 1 s"}, {"start", time_text(13'000)},
       {"end", time_text(20'000)}, {"program_time_s", 300.5}},
      // Ends when the run records again (the queue is part of the hold); placed by the redo.
      {{"state", "interrupted"}, {"reason", "found active at start-up: crash or power loss"},
       {"start", time_text(20'000)}, {"end", time_text(22'000)}, {"program_time_s", 290.0}}};
  EXPECT_EQ(intervals, want) << intervals.dump(1);

  // A run still held (found at start-up, not resumed yet): no end, and no redo has placed it.
  const std::vector<TransitionRow> held(history.begin(), history.begin() + 10);
  const std::vector<EventRow> before_resume(events.begin(), events.begin() + 4);
  const json open = daemon::faulted_intervals(held, before_resume);
  ASSERT_EQ(open.size(), 3u) << open.dump(1);
  EXPECT_EQ(open[1].at("end"), time_text(20'000));
  EXPECT_TRUE(open[2].at("end").is_null());
  EXPECT_TRUE(open[2].at("program_time_s").is_null());
  // Before the first fault, none.
  EXPECT_EQ(daemon::faulted_intervals({history.begin(), history.begin() + 3}, events), json::array());
}

// A run suspended by a chamber fault, then parked by a shutdown and resumed by a new daemon: its
// bundle's meta.json lists both intervals with their reasons, and `imucal import` reads the
// bundle and keeps them.
TEST(RecordingExport, ASuspendedAndInterruptedRunsBundleListsItsFaultedIntervals) {
  LocalDaemon d("export-faulted");
  const auto id = d.post_campaign(
      {{"name", "faulted"}, {"program", "direct-short"}, {"rate_hz", 10}, {"seed", 3}, {"time_scale", 100},
       {"truth", noisy_truth()}, {"estimators", json::array()},
       {"sim_faults", {{{"kind", "chamber_offset"}, {"at_s", 150}, {"duration_s", 20}, {"offset_C", 6}}}}});
  ASSERT_EQ(d.command(id, "start"), 200);
  // Past the fault (the run cannot pass 150 s without suspending on it), then parked.
  d.wait_for(id, [](const json& c) { return c.value("program_time_s", 0.0) > 250.0; });
  d.service->stop();
  d.service.reset();
  d.service = std::make_unique<daemon::Service>(d.config);
  d.service->start(false);
  ASSERT_EQ(d.campaign(id).at("state"), "interrupted");
  ASSERT_EQ(d.command(id, "resume"), 200);
  ASSERT_EQ(d.wait_final(id).at("state"), "done");

  const std::string target = "/api/campaigns/" + std::to_string(id) + "/recording";
  const daemon::HttpReply first = d.call("GET", target);
  ASSERT_EQ(first.status, 202) << "the first request starts the export: " << first.body.substr(0, 300);
  EXPECT_EQ(json::parse(first.body).at("analysis"), "recording");
  const daemon::HttpReply bundle = d.get_computed(target);
  ASSERT_EQ(bundle.status, 200) << bundle.body.substr(0, 300);
  ASSERT_FALSE(bundle.file.empty());

  const std::string dir = d.config.data_dir + "/unpacked";
  std::filesystem::create_directories(dir);
  ASSERT_EQ(shell("tar -xf '" + bundle.file + "' -C '" + dir + "'"), 0);
  const std::string folder = dir + "/campaign-" + std::to_string(id) + "-recording";
  const json meta = json::parse(std::ifstream(folder + "/meta.json"));
  ASSERT_TRUE(meta.contains("faulted_intervals")) << meta.dump(1);
  const json& intervals = meta.at("faulted_intervals");
  ASSERT_EQ(intervals.size(), 2u) << intervals.dump(1);
  const json& suspension = intervals[0];
  EXPECT_EQ(suspension.at("state"), "suspended");
  EXPECT_NE(suspension.at("reason").get<std::string>().find("chamber out of band"), std::string::npos)
      << suspension.dump();
  EXPECT_GE(suspension.at("program_time_s").get<double>(), 150.0);
  EXPECT_LE(suspension.at("program_time_s").get<double>(), 175.0);
  EXPECT_LE(suspension.at("start").get<std::string>(), suspension.at("end").get<std::string>());
  const json& interruption = intervals[1];
  EXPECT_EQ(interruption.at("state"), "interrupted");
  EXPECT_NE(interruption.at("reason").get<std::string>().find("the daemon shut down"), std::string::npos)
      << interruption.dump();
  EXPECT_GT(interruption.at("program_time_s").get<double>(), 170.0);
  EXPECT_LE(suspension.at("end").get<std::string>(), interruption.at("start").get<std::string>());
  EXPECT_LE(interruption.at("start").get<std::string>(), interruption.at("end").get<std::string>());

  // imucal import reads the bundle and keeps the intervals in the run it makes.
  const std::string imported = d.config.data_dir + "/imported.db";
  ASSERT_EQ(shell("'" + imucaltest::program("imucal") + "' import '" + folder + "' --db '" + imported + "' > /dev/null"), 0);
  const auto run = storage::RunDb::open(imported, storage::OpenMode::Read);
  const auto original = storage::RunDb::open(d.config.data_dir + "/" + d.campaign(id).at("run_db").get<std::string>(),
                                             storage::OpenMode::Read);
  EXPECT_EQ(run.frame_count(), original.frame_count());
  EXPECT_EQ(json::parse(run.extra(storage::kFaultedIntervalsKey).value_or("null")), intervals);
}

// While a long run's bundle is written, the HTTP thread (one, the default) answers: health says
// so, and a further job is refused (429) because the export holds the one slot the configuration
// allows. Each such answer is bracketed by two 202s of the export, so it came while the export was
// under way, whatever the machine's load; an export on the HTTP thread would give no 202 at all.
TEST(RecordingExport, HealthAnswersAndTheJobBoundHoldsWhileALongRunsBundleIsWritten) {
  LocalDaemon d("export-long", true, [](daemon::DaemonConfig& c) {
    c.http.threads = 1;
    c.http.max_analysis_jobs = 1;
  });
  const Client viewer{d.service->port(), kViewerToken};
  // The noise program at 100 Hz: 750,000 frames, a bundle of about 100 MB.
  const auto id = d.post_campaign({{"name", "long"}, {"program", "noise"}, {"rate_hz", 100}, {"time_scale", 0},
                                   {"truth", noisy_truth()}, {"estimators", json::array()}});
  ASSERT_EQ(d.command(id, "start"), 200);
  ASSERT_EQ(d.wait_final(id, 900).at("state"), "done");
  const std::string base = "/api/campaigns/" + std::to_string(id);

  HttpResult answer = viewer.get(base + "/recording");
  ASSERT_EQ(answer.status, 202) << answer.body.substr(0, 300);
  EXPECT_EQ(answer.headers.at("retry-after"), "1");
  int bracketed = 0;
  double progress = 0.0;
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::minutes(10);
  while (answer.status == 202 && std::chrono::steady_clock::now() < deadline) {
    const json pending = answer.json_body();
    EXPECT_EQ(pending.at("analysis"), "recording");
    EXPECT_GE(pending.at("progress").get<double>(), progress) << "progress never goes back";
    progress = pending.at("progress").get<double>();
    const HttpResult health = http_request(d.service->port(), "GET", "/api/health");
    ASSERT_EQ(health.status, 200);
    const HttpResult allan = viewer.get(base + "/allan");
    answer = viewer.get(base + "/recording");
    if (answer.status != 202) break;
    ++bracketed;
    EXPECT_EQ(allan.status, 429) << "the export holds the one job slot: " << allan.body.substr(0, 300);
    EXPECT_NE(allan.json_body().value("error", "").find("too many analyses"), std::string::npos) << allan.body;
  }
  ASSERT_EQ(answer.status, 200) << answer.body.substr(0, 300);
  EXPECT_GE(bracketed, 1) << "the export ended before anything could be asked beside it";
  EXPECT_EQ(answer.headers.at("content-type"), "application/x-tar");
  EXPECT_GT(answer.body.size(), 50'000'000u);
  // Ready: the same file at once, HEAD with its length.
  const HttpResult head = http_request(d.service->port(), "HEAD", base + "/recording", "", viewer.auth());
  EXPECT_EQ(head.status, 200);
  EXPECT_EQ(head.headers.at("content-length"), std::to_string(answer.body.size()));
  std::printf("recording bundle of 750,000 frames: %zu bytes; %d health requests answered while it was written\n",
              answer.body.size(), bracketed);
}

// The exports folder is bounded (http.exports_max_bytes): a viewer asking for every run's bundle
// cannot fill the disk. Past the bound the least recently written bundle goes; asked again, it is
// written again (202 first), and the one just written is never the one removed.
TEST(RecordingExport, TheExportsFolderStaysWithinItsBoundAndARemovedBundleIsWrittenAgain) {
  LocalDaemon d("export-bound", false, [](daemon::DaemonConfig& c) { c.http.exports_max_bytes = 1; });
  std::vector<std::int64_t> ids;
  for (const char* name : {"first", "second"}) {
    const auto id = d.post_campaign({{"name", name}, {"program", "direct-short"}, {"rate_hz", 10}, {"seed", 5},
                                     {"time_scale", 0}, {"estimators", json::array()}});
    ASSERT_EQ(d.command(id, "start"), 200);
    ASSERT_EQ(d.wait_final(id).at("state"), "done");
    ids.push_back(id);
  }
  const auto target = [](std::int64_t id) { return "/api/campaigns/" + std::to_string(id) + "/recording"; };
  const daemon::HttpReply first = d.get_computed(target(ids[0]));
  ASSERT_EQ(first.status, 200) << first.body.substr(0, 300);
  ASSERT_TRUE(std::filesystem::exists(first.file));
  const daemon::HttpReply second = d.get_computed(target(ids[1]));
  ASSERT_EQ(second.status, 200) << second.body.substr(0, 300);
  EXPECT_TRUE(std::filesystem::exists(second.file)) << "the bundle just written stays, even alone over the bound";
  EXPECT_FALSE(std::filesystem::exists(first.file)) << "the older bundle was not removed past the bound";
  const daemon::HttpReply again = d.call("GET", target(ids[0]));
  EXPECT_EQ(again.status, 202) << "a removed bundle is written again: " << again.body.substr(0, 300);
  EXPECT_EQ(d.get_computed(target(ids[0])).status, 200);
  EXPECT_TRUE(std::filesystem::exists(first.file));
  EXPECT_FALSE(std::filesystem::exists(second.file));
}
