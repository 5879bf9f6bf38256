// A full disk during a run on the simulated bench (storage::disk_fault: every SQLite write of the
// process, the run file's and the daemon database's alike, fails as on a full file system): the
// disk is filled from the recorder's writer thread once a share of the program is committed, held
// full while the test looks at the suspended run and the API, then given space again. The run
// must resume by itself and end `done` with the file of the same program simulated straight
// through, frame for frame.
#pragma once

#include <atomic>
#include <chrono>
#include <memory>
#include <string>
#include <thread>

#include "service_fixture.hpp"
#include "storage/sqlite.hpp"

namespace imucal::daemontest {

// Never leaves the disk full behind it, whatever the test did.
struct DiskFullSwitch {
  DiskFullSwitch() = default;
  DiskFullSwitch(const DiskFullSwitch&) = delete;
  DiskFullSwitch& operator=(const DiskFullSwitch&) = delete;
  ~DiskFullSwitch() { storage::disk_fault::set_full(false); }
  std::atomic<bool> filled{false};
};

inline std::string telemetry_state(LocalDaemon& d) {
  const json t = d.service->sequencer().telemetry();
  return t.at("run").is_null() ? std::string() : t.at("run").at("state").get<std::string>();
}

struct DiskFullRun {
  json campaign;                 // as stored, after the run
  std::size_t reference_frames = 0;
  double suspended_after_s = 0;  // wall time from the start to the suspension
  int refused_post = 0, pause_while_full = 0, status_while_full = 0;
  std::string refused_post_body, pause_body;
};

// Runs `campaign` and fills the disk once a third of its frames are committed; keeps it full for
// `full_for_s` of wall time after the run is seen suspended, then frees it.
inline DiskFullRun run_with_a_full_disk(LocalDaemon& d, const json& campaign, double full_for_s,
                                        double timeout_s) {
  DiskFullRun out;
  // Shared with the hook, which the run's last recorder may still call after the run is seen done
  // (its final commit at close).
  const auto disk = std::make_shared<DiskFullSwitch>();
  // The program's frames straight through, simulated before the run: its third is where the disk fills.
  std::vector<ImuFrame> want;
  {
    const auto id = d.post_campaign(campaign);
    want = reference_frames(d.campaign(id).at("spec"), d.config);
    out.reference_frames = want.size();
    const std::int64_t fill_at = static_cast<std::int64_t>(want.size() / 3);
    daemon::Sequencer::RecorderHooks hooks;
    hooks.after_commit = [disk, fill_at](const storage::RecorderStats& s) {
      if (!disk->filled.load() && s.stored_frames >= fill_at) {
        disk->filled = true;
        storage::disk_fault::set_full(true);
      }
    };
    d.service->sequencer().set_recorder_hooks(hooks);
    const auto started = std::chrono::steady_clock::now();
    EXPECT_EQ(d.command(id, "start"), 200);

    // Suspended: the daemon database cannot take the transition either, so the sequencer's own
    // state (the live telemetry) is where it shows until space returns.
    const auto deadline = started + std::chrono::duration<double>(timeout_s);
    while (telemetry_state(d) != "suspended" && std::chrono::steady_clock::now() < deadline)
      std::this_thread::sleep_for(std::chrono::milliseconds(5));
    out.suspended_after_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - started).count();
    EXPECT_TRUE(disk->filled.load()) << "the disk was never filled";
    EXPECT_EQ(telemetry_state(d), "suspended") << "the run did not suspend on the full disk";

    // The service answers while the disk is full: reads as usual, changes with 503 and the reason.
    out.status_while_full = d.call("GET", "/api/status").status;
    const auto post = d.call("POST", "/api/campaigns", campaign.dump());
    out.refused_post = post.status;
    out.refused_post_body = post.body;
    // A command on the run is checked against the sequencer's state, which the database is behind.
    const auto pause = d.call("POST", "/api/campaigns/" + std::to_string(id) + "/pause");
    out.pause_while_full = pause.status;
    out.pause_body = pause.body;
    std::this_thread::sleep_for(std::chrono::duration<double>(full_for_s));  // failed retries meanwhile
    EXPECT_EQ(telemetry_state(d), "suspended") << "the run went on while the disk was full";
    storage::disk_fault::set_full(false);

    out.campaign = d.wait_final(id, timeout_s);
  }
  d.service->sequencer().set_recorder_hooks({});
  const json& c = out.campaign;
  EXPECT_EQ(c.at("state"), "done") << c.dump().substr(0, 3000);
  if (c.at("state") != "done") return out;
  EXPECT_TRUE(has_transition(c, "running", "suspended"));
  EXPECT_TRUE(has_transition(c, "suspended", "running"));
  EXPECT_TRUE(has_event(c, "suspended", "disk full: at least")) << c.at("events").dump().substr(0, 3000);
  EXPECT_TRUE(has_event(c, "resumed", "redoing segment")) << c.at("events").dump().substr(0, 4000);
  // The operator's alarm, stored once the disk took it, cleared with the resumption.
  bool alarm = false;
  for (const auto& a : c.at("alarms"))
    if (a.at("message").get<std::string>().find("disk full: at least") != std::string::npos &&
        a.at("message").get<std::string>().find("MB free needed") != std::string::npos)
      alarm = true;
  EXPECT_TRUE(alarm) << c.at("alarms").dump().substr(0, 3000);
  EXPECT_EQ(c.at("lost_frames"), 0);
  // Every frame once, bit for bit: nothing lost with the failed batches, nothing recorded twice
  // by the redo; one writer session (the run file was never reopened), no gap.
  expect_same_frames(run_frames(d.run_path(c)), want);
  const auto db = storage::RunDb::open(d.run_path(c), storage::OpenMode::Read);
  EXPECT_EQ(db.sessions().size(), 1u);
  EXPECT_TRUE(db.dropped_spans().empty());
  return out;
}

}  // namespace imucal::daemontest
