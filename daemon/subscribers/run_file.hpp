// The run file: the recording the run loop writes frames into (RunRecording over storage's
// Recorder and RunDb), and the subscriber that keeps the run's own record in it (its transitions
// and events, its faulted intervals as the exported bundle's meta.json lists them, the estimators'
// results and model), so that the file alone tells what happened to the run.
#pragma once

#include <cstdint>
#include <functional>
#include <mutex>
#include <optional>
#include <string>

#include "daemon/config/config.hpp"
#include "daemon/db/daemon_db.hpp"
#include "daemon/devices/devices.hpp"
#include "daemon/run/documents.hpp"
#include "daemon/run/recording.hpp"
#include "storage/recorder.hpp"

namespace imucal::daemon {

class StorageRecording;

// A simulated bench's disk_full fault fills storage's full-disk switch.
DiskFaultSwitch storage_disk_switch();

class RunFiles final : public RecordingFactory, public RunSubscriber {
 public:
  // Seams for tests that need a slow or a full disk under a run; none in service.
  struct Hooks {
    // Called with the run file before each recording of a run takes it: attempt 0 at the start,
    // 1, 2, ... each time the file is reopened after a write failure.
    std::function<void(storage::RunDb&, int attempt)> on_open;
    // Called on the writer thread after every commit.
    std::function<void(const storage::RecorderStats&)> after_commit;
    // Overrides the bench: false drops frames on a full queue, as with real devices.
    std::optional<bool> wait_when_full;
  };

  RunFiles(const DaemonConfig& config, DaemonDb& db) : config_(config), db_(db) {}
  void set_hooks(Hooks hooks);

  RecordingOpened open(const Request& request) override;

  void start(const RunStart& start) override;
  void event(const RunEvent& event) override;
  void transition(const Transition& transition) override;
  void results(const RunResults& results) override;
  void stop(const RunStop& stop) override;

 private:
  friend class StorageRecording;
  void forget(const StorageRecording* recording);
  // The run's record into its file (the current recording's, when it is campaign's).
  void write_record(std::int64_t campaign);
  void write_record_locked(std::int64_t campaign);

  const DaemonConfig& config_;
  DaemonDb& db_;
  std::mutex mutex_;  // guards the members below
  Hooks hooks_;
  std::int64_t opens_campaign_ = 0;
  int opens_ = 0;  // recordings started on the run file in this run
  StorageRecording* current_ = nullptr;
  std::string name_;  // the current run's campaign name
};

}  // namespace imucal::daemon
