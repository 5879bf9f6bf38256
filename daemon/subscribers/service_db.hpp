// The service database's subscriber: what a run's documents say, kept in the daemon database
// (the campaign's state while it runs, its events, checkpoints, counters, the estimators'
// progress and results, its error), every write through the service's WriteQueue so that a full
// disk defers it in order instead of failing the run. Subscribed first: what the others show is
// stored.
#pragma once

#include <chrono>
#include <mutex>

#include <nlohmann/json.hpp>

#include "daemon/db/daemon_db.hpp"
#include "daemon/db/write_queue.hpp"
#include "daemon/run/documents.hpp"

namespace imucal::daemon {

class ServiceDbSubscriber final : public RunSubscriber {
 public:
  ServiceDbSubscriber(DaemonDb& db, WriteQueue& writes) : db_(db), writes_(writes) {}

  void start(const RunStart& start) override;
  void transition(const Transition& transition) override;
  void event(const RunEvent& event) override;
  void checkpoint(const Checkpoint& checkpoint) override;
  void snapshot(const Snapshot& snapshot) override;
  void progress(const EstimatorProgress& progress) override;
  void results(const RunResults& results) override;
  void error(const RunError& error) override;
  void stop(const RunStop& stop) override;

 private:
  DaemonDb& db_;
  WriteQueue& writes_;
  std::chrono::steady_clock::time_point last_counters_{};  // the run's thread only
  std::mutex estimators_mutex_;
  nlohmann::json estimators_ = nlohmann::json::object();  // the latest progress of each, this run
};

}  // namespace imucal::daemon
