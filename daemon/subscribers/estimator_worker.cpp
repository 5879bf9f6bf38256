#include "daemon/subscribers/estimator_worker.hpp"

#include <chrono>
#include <algorithm>
#include <cmath>
#include <limits>
#include <map>
#include <memory>

#include <spdlog/spdlog.h>

#include "core/units.hpp"
#include "daemon/campaign/campaign.hpp"
#include "daemon/db/daemon_db.hpp"
#include "estimators/navigation_run.hpp"
#include "pipeline/pipeline.hpp"
#include "storage/run_db.hpp"

namespace imucal::daemon {

using nlohmann::json;
using Clock = std::chrono::steady_clock;

EstimatorWorker::EstimatorWorker(std::string run_db_path, Spec spec, std::optional<std::int64_t> committed_t_ns, Sink sink)
    : path_(std::move(run_db_path)), spec_(std::move(spec)), sink_(std::move(sink)) {
  if (committed_t_ns) target_t_ns_ = *committed_t_ns;
  thread_ = std::thread([this] {
    run();
    std::lock_guard lock(mutex_);
    done_ = true;
    done_cv_.notify_all();
  });
}

EstimatorWorker::~EstimatorWorker() { cancel(); }

EstimatorWorker::Spec estimator_spec(const CampaignSpec& spec, DaemonDb& db) {
  EstimatorWorker::Spec out{spec.estimators, spec.navigation_model, spec.start_model.value_or(ImuModel{})};
  if (spec.start_model_campaign) {
    const std::string id = std::to_string(*spec.start_model_campaign);
    const auto source = db.campaign(*spec.start_model_campaign);
    if (!source || !source->model_json)
      throw std::runtime_error("campaign.model names campaign " + id + ", which " +
                               (source ? "has no model" : "does not exist"));
    out.start_model = imu_model_from_json_text(*source->model_json, "campaign " + id + "'s model");
  }
  return out;
}

void EstimatorWorker::committed(std::int64_t t_ns) {
  {
    std::lock_guard lock(mutex_);
    target_t_ns_ = std::max(target_t_ns_, t_ns);
  }
  cv_.notify_one();
}

EstimatorWorker::Results EstimatorWorker::finish(std::optional<std::int64_t> final_t_ns,
                                                 const std::function<void()>& while_waiting) {
  {
    std::unique_lock lock(mutex_);
    if (final_t_ns) target_t_ns_ = std::max(target_t_ns_, *final_t_ns);
    finishing_ = true;
    cv_.notify_one();
    while (!done_ && while_waiting) {
      // The caller's wait is what it shows meanwhile (the sequencer: telemetry, so the page follows
      // the estimators through the tail of a run they lag behind).
      if (done_cv_.wait_for(lock, std::chrono::milliseconds(200), [&] { return done_; })) break;
      lock.unlock();
      while_waiting();
      lock.lock();
    }
  }
  if (thread_.joinable()) thread_.join();
  return results_;
}

bool EstimatorWorker::cancel_requested() {
  std::lock_guard lock(mutex_);
  return cancelled_;
}

void EstimatorWorker::cancel() {
  {
    std::lock_guard lock(mutex_);
    cancelled_ = true;
  }
  cv_.notify_one();
  if (thread_.joinable()) thread_.join();
}

namespace {

// The worker's feeding steps (see `feed` in run()).
constexpr std::int64_t kFeedStep_ns = 5'000'000'000;
constexpr std::int64_t kMaxFeedSteps = 1000;

bool listed(const std::vector<std::string>& names, const char* name) {
  return std::find(names.begin(), names.end(), name) != names.end();
}

// Free-inertial navigation of the whole run against the table reference (the `navigation`
// estimator): the largest horizontal errors so far.
class NavigationMonitor {
 public:
  NavigationMonitor(const RecordingMeta& meta, const ImuModel& model)
      : run_(meta, model, 1.0, [this](const nav::NavErrorSample& e) {
          t_s_ = e.t_s;
          max_v_ = std::max(max_v_, std::hypot(e.dv_n_mps.x(), e.dv_n_mps.y()));
          max_p_ = std::max(max_p_, std::hypot(e.dp_n_m.x(), e.dp_n_m.y()));
        }) {}
  void feed(const pipeline::FrameSource& source, std::int64_t available_t_ns) {
    if (state_["status"] == "failed") return;
    try {
      feeder_.feed(
          source, available_t_ns, [&](const TempSample& t) { run_.push_temp(t); }, [&](const ImuFrame& f) { run_.push(f); });
      if (feeder_.fed_t_ns()) state_["status"] = "running";
    } catch (const std::exception& e) {
      state_["status"] = "failed";
      state_["message"] = e.what();
    }
  }
  const json& progress() {
    state_["program_time_s"] = t_s_;
    state_["max_velocity_error_mps"] = max_v_;
    state_["max_position_error_m"] = max_p_;
    return state_;
  }
  json finish() {
    if (state_["status"] == "failed") return {{"status", "failed"}, {"message", state_["message"]}};
    try {
      const nav::NavSummary s = run_.finish();
      state_["status"] = "done";
      return {{"status", "done"},
              {"duration_s", s.duration_s},
              {"frames", s.frames},
              {"max_velocity_error_mps", s.max_velocity_error_mps},
              {"max_position_error_m", s.max_position_error_m},
              {"max_attitude_error_arcsec", s.max_attitude_error_rad * units::kRadToArcsec}};
    } catch (const std::exception& e) {
      state_["status"] = "failed";
      state_["message"] = e.what();
      return {{"status", "failed"}, {"message", e.what()}};
    }
  }

 private:
  nav::NavigationRun run_;
  pipeline::Feeder feeder_;
  double max_v_ = 0.0, max_p_ = 0.0, t_s_ = 0.0;
  json state_ = {{"status", "waiting"}, {"message", nullptr}};
};

}  // namespace

void EstimatorWorker::run() {
  std::unique_ptr<storage::RunDb> db;
  RecordingMeta meta;
  try {
    // Read-only: the worker must never become the run's writer (the recorder holds the lease).
    db = std::make_unique<storage::RunDb>(storage::RunDb::open(path_, storage::OpenMode::Read));
    meta = db->meta();
  } catch (const std::exception& e) {
    spdlog::error("estimators: cannot open the run: {}", e.what());
    std::lock_guard lock(mutex_);
    for (const auto& name : spec_.estimators) results_.results[name] = {{"status", "failed"}, {"message", e.what()}};
    return;
  }
  const pipeline::RunDbSource source(*db);

  // The calibration stages asked for, as one pipeline: each starts from the model of the ones before.
  std::vector<pipeline::Stage> stages;
  for (const auto& name : spec_.estimators)
    if (const auto stage = pipeline::stage_of_estimator(name)) stages.push_back(*stage);
  std::unique_ptr<pipeline::Pipeline> calibration;
  std::unique_ptr<NavigationMonitor> monitor;
  try {
    if (!stages.empty())
      calibration = std::make_unique<pipeline::Pipeline>(meta, stages, true, spec_.start_model);
    if (listed(spec_.estimators, "navigation"))
      monitor = std::make_unique<NavigationMonitor>(meta, spec_.navigation_model.value_or(ImuModel{}));
  } catch (const std::exception& e) {
    spdlog::error("estimators: {}", e.what());
    std::lock_guard lock(mutex_);
    for (const auto& name : spec_.estimators) results_.results[name] = {{"status", "failed"}, {"message", e.what()}};
    return;
  }

  std::optional<std::int64_t> fed_t_ns;
  auto last_report = Clock::now() - std::chrono::seconds(10);
  double last_report_t_s = -std::numeric_limits<double>::infinity();
  // Progress of each estimator, when it changed (a finished or waiting stage stays quiet).
  std::map<std::string, json> sent;
  auto report = [&] {
    const double t_s = fed_t_ns ? static_cast<double>(*fed_t_ns) / units::kNsPerS : 0.0;
    auto send = [&](const std::string& name, const json& progress) {
      json& last = sent[name];
      if (last == progress) return;
      last = progress;
      sink_(name, t_s, progress);
    };
    if (calibration)
      for (pipeline::Stage stage : stages) send(pipeline::names_of(stage).estimator, calibration->progress(stage));
    if (monitor) send("navigation", monitor->progress());
  };
  // At most every 500 ms of wall time and 5 s of program time: each report is stored in the
  // daemon's database (stage 3's holds every state: about 5 kB), so a real-time run of the
  // navigation program stores about 1700, not 17 000.
  auto report_now_and_then = [&] {
    const double fed_s = fed_t_ns ? static_cast<double>(*fed_t_ns) / units::kNsPerS : 0.0;
    if (Clock::now() - last_report < std::chrono::milliseconds(500) || fed_s - last_report_t_s < 5.0) return;
    report();
    last_report = Clock::now();
    last_report_t_s = fed_s;
  };
  // Fed in steps of a few seconds of program time, reporting between them: a worker behind the run
  // (a fast time scale, a resumed run's replay, the tail after the program ended) still shows its
  // progress as it goes, not one jump at the end. The consumers see the same frames however they
  // are split (pipeline::Feeder), so the results do not depend on the steps.
  auto feed = [&](std::int64_t upto_t_ns, bool final) {
    const std::int64_t from_t_ns = fed_t_ns.value_or(std::min<std::int64_t>(0, upto_t_ns));
    const std::int64_t step_ns = std::max<std::int64_t>(kFeedStep_ns, (upto_t_ns - from_t_ns) / kMaxFeedSteps);
    std::int64_t t_ns = from_t_ns;
    do {
      t_ns = upto_t_ns - t_ns > step_ns ? t_ns + step_ns : upto_t_ns;
      if (calibration) calibration->advance(source, t_ns, final && t_ns == upto_t_ns);
      if (monitor) monitor->feed(source, t_ns);
      fed_t_ns = t_ns;
      if (t_ns == upto_t_ns) return;
      report_now_and_then();
    } while (!cancel_requested());
  };

  try {
    for (;;) {
      std::int64_t target;
      bool finishing;
      {
        std::unique_lock lock(mutex_);
        cv_.wait(lock, [&] {
          return cancelled_ || finishing_ || (target_t_ns_ != std::numeric_limits<std::int64_t>::min() &&
                                               (!fed_t_ns || target_t_ns_ > *fed_t_ns));
        });
        if (cancelled_) return;
        target = target_t_ns_;
        finishing = finishing_;
      }
      if (finishing) {
        feed(target, true);
        break;
      }
      if (target != std::numeric_limits<std::int64_t>::min()) feed(target, false);
      if (cancel_requested()) return;
      report_now_and_then();
    }
    if (cancel_requested()) return;
    // Final results: each stage's report (its model included) under its estimator's name.
    Results out;
    if (calibration) {
      pipeline::Calibration c = pipeline::calibration_of(calibration->outcomes());
      out.results = std::move(c.reports);
      out.model = std::move(c.model);
    }
    if (monitor) out.results["navigation"] = monitor->finish();
    report();
    std::lock_guard lock(mutex_);
    results_ = std::move(out);
  } catch (const std::exception& e) {
    spdlog::error("estimators: {}", e.what());
    std::lock_guard lock(mutex_);
    for (const auto& name : spec_.estimators) results_.results[name] = {{"status", "failed"}, {"message", e.what()}};
  }
}

}  // namespace imucal::daemon
