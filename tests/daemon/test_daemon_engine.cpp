// The run engine's documents (daemon/run/documents.hpp), as a subscriber added to the sequencer
// sees them for a whole run on the simulated bench: each kind when it is due, in the order the
// architecture promises (docs/ARCHITECTURE.md "The run engine"), and the figures they carry the
// same as what the service database stored.
#include <gtest/gtest.h>

#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <future>
#include <mutex>
#include <thread>
#include <string>
#include <vector>

#include "daemon/run/documents.hpp"
#include "service_fixture.hpp"

using namespace imucal;
using namespace imucal::daemontest;

namespace {

// Every document of one campaign, by name, with what the test checks of it.
class Journal final : public daemon::RunSubscriber {
 public:
  explicit Journal(std::int64_t campaign) : campaign_(campaign) {}
  struct Entry {
    std::string kind;
    json detail;
  };
  std::vector<Entry> entries() const {
    std::lock_guard lock(mutex_);
    return entries_;
  }

  void start(const daemon::RunStart& d) override {
    add(d.campaign, "start", {{"resuming", d.resuming}, {"run_file", d.run_file_relative}});
  }
  void transition(const daemon::Transition& d) override {
    add(d.campaign, "transition",
        {{"from", daemon::to_string(d.from)}, {"to", daemon::to_string(d.to)}, {"stored", d.stored}});
  }
  void event(const daemon::RunEvent& d) override { add(d.campaign, "event", {{"kind", d.kind}}); }
  void checkpoint(const daemon::Checkpoint& d) override {
    add(d.campaign, "checkpoint", {{"segment", d.segment}, {"t_s", d.t_s}});
  }
  void snapshot(const daemon::Snapshot& d) override {
    add(d.campaign, "snapshot", {{"force", d.force}, {"frames", d.counters.frames}});
  }
  void frames_committed(const daemon::FramesCommitted& d) override { add(d.campaign, "committed", {{"t_ns", d.t_ns}}); }
  void progress(const daemon::EstimatorProgress& d) override { add(d.campaign, "progress", {{"estimator", d.estimator}}); }
  void ending(const daemon::RunEnding& d) override { add(d.campaign, "ending", {{"results", d.results}}); }
  void results(const daemon::RunResults& d) override {
    add(d.campaign, "results", {{"failed", d.failed}, {"model", d.model_json.has_value()}});
  }
  void error(const daemon::RunError& d) override { add(d.campaign, "error", {{"why", d.why}}); }
  void stop(const daemon::RunStop& d) override {
    add(d.campaign, "stop", {{"frames", d.counters.frames}, {"complete", d.complete ? json(*d.complete) : json()}});
  }

 private:
  void add(std::int64_t campaign, const std::string& kind, json detail) {
    if (campaign != campaign_) return;
    std::lock_guard lock(mutex_);
    entries_.push_back({kind, std::move(detail)});
  }
  std::int64_t campaign_;
  mutable std::mutex mutex_;
  std::vector<Entry> entries_;
};

}  // namespace

namespace {

// Written as small pieces: clang 16's optional-access analysis (the static check) costs minutes on
// one function that loops and branches over many checks.

// Stored first (the service database is the first subscriber): the run has given its last
// document only when the sequencer has no active run any more.
bool wait_until_idle(LocalDaemon& d) {
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(60);
  while (d.service->sequencer().active_id().has_value() && std::chrono::steady_clock::now() < deadline)
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  return !d.service->sequencer().active_id().has_value();
}

// The operator's start and the claim are stored by the sequencer before they are told; the run's
// own changes are the service database subscriber's to store. The run's last transition comes
// last but for the telemetry of the parked bench and the run file's closing commit.
void expect_transitions(const std::vector<Journal::Entry>& entries) {
  ASSERT_GE(entries.size(), 2u);
  EXPECT_EQ(entries.front().kind, "transition");
  EXPECT_EQ(entries.front().detail, (json{{"from", "created"}, {"to", "queued"}, {"stored", true}}));
  EXPECT_EQ(entries.at(1).detail, (json{{"from", "queued"}, {"to", "running"}, {"stored", true}}));
  std::size_t last = entries.size();
  for (std::size_t k = 0; k < entries.size(); ++k)
    if (entries[k].kind == "transition") last = k;
  ASSERT_LT(last, entries.size());
  EXPECT_EQ(entries[last].detail, (json{{"from", "running"}, {"to", "done"}, {"stored", false}}));
  for (std::size_t k = last + 1; k < entries.size(); ++k)
    EXPECT_TRUE(entries[k].kind == "snapshot" || entries[k].kind == "committed") << entries[k].kind;
}

// Start, then the segments' checkpoints in order, then the ending, the results and the stop
// (snapshots, commits, progress and events come in between).
void expect_milestones(const std::vector<Journal::Entry>& entries, std::size_t segment_count) {
  std::vector<std::string> milestones;
  std::vector<std::int64_t> segments;
  double last_checkpoint_s = -1.0;
  for (const auto& e : entries) {
    if (e.kind == "start" || e.kind == "ending" || e.kind == "results" || e.kind == "stop") milestones.push_back(e.kind);
    if (e.kind != "checkpoint") continue;
    if (milestones.size() == 1) milestones.push_back("checkpoints");
    segments.push_back(e.detail.at("segment").get<std::int64_t>());
    EXPECT_GT(e.detail.at("t_s").get<double>(), last_checkpoint_s);
    last_checkpoint_s = e.detail.at("t_s").get<double>();
  }
  EXPECT_EQ(milestones, (std::vector<std::string>{"start", "checkpoints", "ending", "results", "stop"}));
  ASSERT_EQ(segments.size(), segment_count);
  for (std::size_t k = 0; k < segments.size(); ++k) EXPECT_EQ(segments[k], static_cast<std::int64_t>(k));
}

// What the documents carry is what was stored.
void expect_carried(const std::vector<Journal::Entry>& entries, std::int64_t id, const json& campaign) {
  for (const auto& e : entries) {
    if (e.kind == "start") {
      EXPECT_EQ(e.detail, (json{{"resuming", false}, {"run_file", "runs/" + std::to_string(id) + ".db"}}));
    } else if (e.kind == "ending") {
      EXPECT_TRUE(e.detail.at("results").get<bool>());
    } else if (e.kind == "results") {
      EXPECT_EQ(e.detail, (json{{"failed", false}, {"model", true}}));
    } else if (e.kind == "stop") {
      EXPECT_EQ(e.detail, (json{{"frames", campaign.at("frames")}, {"complete", true}}));
    }
    EXPECT_NE(e.kind, "error");
  }
}

// The run file's commits only go forward, up to its last frame; the estimators reported; the
// moments that must be seen were snapshots of their own.
void expect_commits_progress_snapshots(const std::vector<Journal::Entry>& entries, std::int64_t last_frame_t_ns) {
  std::int64_t committed_t_ns = -1;
  int progress = 0, forced = 0;
  for (const auto& e : entries) {
    if (e.kind == "committed") {
      EXPECT_GE(e.detail.at("t_ns").get<std::int64_t>(), committed_t_ns);
      committed_t_ns = e.detail.at("t_ns").get<std::int64_t>();
    }
    progress += e.kind == "progress";
    forced += e.kind == "snapshot" && e.detail.at("force").get<bool>();
  }
  EXPECT_EQ(committed_t_ns, last_frame_t_ns);
  EXPECT_GE(progress, 1);
  EXPECT_GE(forced, 2);  // the parked table before the end is seen, and the final state
}

}  // namespace

TEST(RunEngine, AWholeRunEmitsEveryDocumentInItsOrder) {
  LocalDaemon d("engine-documents");
  const json campaign = {{"name", "documents"}, {"program", "direct-short"}, {"rate_hz", 100}, {"seed", 3},
                         {"time_scale", 0}, {"truth", noisy_truth()}, {"estimators", {"direct"}}};
  const auto id = d.post_campaign(campaign);
  Journal journal(id);
  d.service->sequencer().subscribe(journal);
  ASSERT_EQ(d.command(id, "start"), 200);
  const json c = d.wait_final(id);
  ASSERT_EQ(c.at("state"), "done") << c.dump();
  ASSERT_TRUE(wait_until_idle(d));
  const auto entries = journal.entries();
  std::string kinds;  // what a failure shows: the documents in the order they came
  for (const auto& e : entries) kinds += (e.kind == "transition" ? e.detail.dump() : e.kind) + " ";
  SCOPED_TRACE("documents: " + kinds);
  expect_transitions(entries);
  expect_milestones(entries, c.at("segments").size());
  expect_carried(entries, id, c);
  const auto frames = run_frames(d.run_path(c));
  ASSERT_FALSE(frames.empty());
  expect_commits_progress_snapshots(entries, frames.back().t_ns);
}

TEST(RunEngine, ASubscriberIsRefusedWhileARunIsActive) {
  LocalDaemon d("engine-subscribe");
  const json campaign = {{"name", "busy"}, {"program", "direct-short"}, {"rate_hz", 100}, {"seed", 4},
                         {"time_scale", 20}, {"truth", noisy_truth()}, {"estimators", json::array()}};
  const auto id = d.post_campaign(campaign);
  ASSERT_EQ(d.command(id, "start"), 200);
  d.wait_for(id, [](const json& c) { return c.at("state") == "running"; });
  Journal late(id);
  EXPECT_THROW(d.service->sequencer().subscribe(late), std::logic_error);
  ASSERT_EQ(d.command(id, "abort"), 200);
  EXPECT_EQ(d.wait_final(id).at("state"), "aborted");
}

namespace {

// Reads the sequencer while it is given a transition, slowly, as the certificate of a run that
// ends reads the campaign's prompt.
class SlowReader final : public daemon::RunSubscriber {
 public:
  explicit SlowReader(daemon::Sequencer& sequencer) : sequencer_(sequencer) {}
  void transition(const daemon::Transition& d) override {
    std::this_thread::sleep_for(std::chrono::milliseconds(150));
    (void)sequencer_.prompt_of(d.campaign);
    std::lock_guard lock(mutex_);
    order_.push_back(d.campaign);
  }
  std::vector<std::int64_t> order() const {
    std::lock_guard lock(mutex_);
    return order_;
  }

 private:
  daemon::Sequencer& sequencer_;
  mutable std::mutex mutex_;
  std::vector<std::int64_t> order_;
};

}  // namespace

// Two commands at once: the second's change waits for the first to be delivered, and must not
// hold what the first's subscriber reads meanwhile (CI hung on this: the certificate at the end
// of a run read the prompt while an operator's command waited its turn).
TEST(RunEngine, ASubscriberReadsTheSequencerWhileAnotherChangeWaitsItsTurn) {
  LocalDaemon d("engine-reader");
  SlowReader reader(d.service->sequencer());
  d.service->sequencer().subscribe(reader);
  const json campaign = {{"name", "idle"}, {"program", "direct-short"}, {"rate_hz", 100}, {"seed", 5},
                         {"time_scale", 0}, {"truth", noisy_truth()}, {"estimators", json::array()}};
  const auto first = d.post_campaign(campaign);
  const auto second = d.post_campaign(campaign);
  auto both = std::async(std::launch::async, [&] {
    std::thread other([&] {
      std::this_thread::sleep_for(std::chrono::milliseconds(50));  // while the first is delivered
      EXPECT_EQ(d.command(second, "abort"), 200);
    });
    EXPECT_EQ(d.command(first, "abort"), 200);
    other.join();
  });
  if (both.wait_for(std::chrono::seconds(120)) != std::future_status::ready) {
    std::fprintf(stderr, "deadlock: two commands and a subscriber reading the sequencer never finished\n");
    std::_Exit(1);  // the threads cannot be joined: fail now rather than at ctest's timeout
  }
  EXPECT_EQ(reader.order().size(), 2u);
  EXPECT_EQ(d.campaign(first).at("state"), "aborted");
  EXPECT_EQ(d.campaign(second).at("state"), "aborted");
}
