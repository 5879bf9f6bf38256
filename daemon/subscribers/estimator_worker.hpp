// Online estimators on a worker thread. The worker does not take frames from the sequencer: it
// tails the run database (its own read connection, WAL) up to what the recorder has committed.
// So it never blocks recording whatever its speed, its memory stays bounded, and after a restart
// it replays the committed frames with the same code before following the new ones. The
// calibration estimators (direct, lever-arm, stage3) are the calibration pipeline of
// `imucal calibrate` (pipeline/), advanced as the file grows; `navigation` is the free-inertial
// navigation against the table reference, a display of how well a given model navigates.
#pragma once

#include <atomic>
#include <condition_variable>
#include <cstdint>
#include <functional>
#include <limits>
#include <mutex>
#include <optional>
#include <string>
#include <thread>
#include <vector>

#include <nlohmann/json.hpp>

#include "core/imu_model.hpp"

namespace imucal::daemon {

struct CampaignSpec;
class DaemonDb;

class EstimatorWorker {
 public:
  // Progress of one estimator (the live message's estimators.<name> block); called on the
  // worker thread, at most about once a second per estimator.
  using Sink = std::function<void(const std::string& estimator, double program_time_s, const nlohmann::json& progress)>;

  struct Results {
    // The last calibration stage's model (stage 1: instrument frame; stage 3: body frame), with
    // sigma; each stage's own is in its results entry ("model").
    std::optional<ImuModel> model;
    nlohmann::json results = nlohmann::json::object();  // per estimator: its report or why there is none
  };

  struct Spec {
    std::vector<std::string> estimators;
    std::optional<ImuModel> navigation_model;  // the free-inertial display's model (ideal by default)
    ImuModel start_model;                      // the first calibration stage's (ideal by default)
  };

  // `committed_t_ns`: frames already committed in the file (replayed first); nothing when empty.
  EstimatorWorker(std::string run_db_path, Spec spec, std::optional<std::int64_t> committed_t_ns, Sink sink);
  ~EstimatorWorker();
  EstimatorWorker(const EstimatorWorker&) = delete;
  EstimatorWorker& operator=(const EstimatorWorker&) = delete;

  // The recorder committed frames up to t_ns (thread-safe, never blocks).
  void committed(std::int64_t t_ns);
  // Feeds everything committed up to `final_t_ns`, finishes every estimator and ends the thread.
  // `while_waiting`, when given, is called about every 200 ms until then (on the caller's thread).
  Results finish(std::optional<std::int64_t> final_t_ns, const std::function<void()>& while_waiting = {});
  // Ends the thread without results (abort, shutdown).
  void cancel();

 private:
  void run();
  bool cancel_requested();

  std::string path_;
  Spec spec_;
  Sink sink_;

  std::mutex mutex_;
  std::condition_variable cv_;
  std::condition_variable done_cv_;  // done_ set: run() has returned
  bool done_ = false;
  std::int64_t target_t_ns_ = std::numeric_limits<std::int64_t>::min();
  bool finishing_ = false, cancelled_ = false;
  Results results_;
  std::thread thread_;
};

// The estimators of a campaign as its run starts them: its list, its navigation model and its start
// model (a previous campaign's model as that campaign has it now). The run and a run calibrated
// again from its recording resolve them alike. Throws std::runtime_error when the campaign it
// names has no model.
EstimatorWorker::Spec estimator_spec(const CampaignSpec& spec, DaemonDb& db);

}  // namespace imucal::daemon
