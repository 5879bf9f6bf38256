#include "daemon/service/estimator_worker.hpp"

#include <chrono>
#include <deque>
#include <limits>
#include <memory>

#include <spdlog/spdlog.h>

#include "core/units.hpp"
#include "daemon/service/campaign.hpp"
#include "estimators/direct_calibration.hpp"
#include "estimators/navigation_run.hpp"
#include "storage/run_db.hpp"

namespace imucal::daemon {

using nlohmann::json;
using Clock = std::chrono::steady_clock;

EstimatorWorker::EstimatorWorker(std::string run_db_path, std::vector<std::string> estimators,
                                 std::optional<ImuModel> navigation_model, std::optional<std::int64_t> committed_t_ns,
                                 Sink sink)
    : path_(std::move(run_db_path)),
      estimators_(std::move(estimators)),
      navigation_model_(std::move(navigation_model)),
      sink_(std::move(sink)) {
  if (committed_t_ns) target_t_ns_ = *committed_t_ns;
  thread_ = std::thread([this] { run(); });
}

EstimatorWorker::~EstimatorWorker() { cancel(); }

void EstimatorWorker::committed(std::int64_t t_ns) {
  {
    std::lock_guard lock(mutex_);
    target_t_ns_ = std::max(target_t_ns_, t_ns);
  }
  cv_.notify_one();
}

EstimatorWorker::Results EstimatorWorker::finish(std::optional<std::int64_t> final_t_ns) {
  {
    std::lock_guard lock(mutex_);
    if (final_t_ns) target_t_ns_ = std::max(target_t_ns_, *final_t_ns);
    finishing_ = true;
  }
  cv_.notify_one();
  if (thread_.joinable()) thread_.join();
  return results_;
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

bool listed(const std::vector<std::string>& names, const char* name) {
  return std::find(names.begin(), names.end(), name) != names.end();
}

}  // namespace

void EstimatorWorker::run() {
  const bool want_direct = listed(estimators_, "direct");
  const bool want_nav = listed(estimators_, "navigation");
  std::unique_ptr<storage::RunDb> db;
  RecordingMeta meta;
  try {
    // Read-only: the worker must never become the run's writer (the recorder holds the lease).
    db = std::make_unique<storage::RunDb>(storage::RunDb::open(path_, storage::OpenMode::Read));
    meta = db->meta();
  } catch (const std::exception& e) {
    spdlog::error("estimators: cannot open the run: {}", e.what());
    std::lock_guard lock(mutex_);
    for (const auto& name : estimators_) results_.results[name] = {{"status", "failed"}, {"message", e.what()}};
    return;
  }

  std::unique_ptr<direct::DirectCalibrator> direct_cal;
  json direct_state = {{"status", "waiting"}, {"statics", 0}, {"rotations", 0}, {"program_time_s", 0.0},
                       {"estimates", json::object()}, {"message", nullptr}};
  if (want_direct) direct_cal = std::make_unique<direct::DirectCalibrator>(meta);

  std::unique_ptr<nav::NavigationRun> nav_run;
  const ImuModel nav_model = navigation_model_.value_or(ImuModel{});
  double nav_max_v = 0.0, nav_max_p = 0.0, nav_t_s = 0.0;
  json nav_state = {{"status", "waiting"}, {"program_time_s", 0.0}, {"max_velocity_error_mps", 0.0},
                    {"max_position_error_m", 0.0}, {"message", nullptr}};
  if (want_nav) {
    nav_run = std::make_unique<nav::NavigationRun>(meta, nav_model, 1.0, [&](const nav::NavErrorSample& e) {
      nav_t_s = e.t_s;
      nav_max_v = std::max(nav_max_v, std::hypot(e.dv_n_mps.x(), e.dv_n_mps.y()));
      nav_max_p = std::max(nav_max_p, std::hypot(e.dp_n_m.x(), e.dp_n_m.y()));
    });
  }

  std::optional<std::int64_t> fed_t_ns;
  // The navigation model's thermal section (stage 2) needs the temperatures with the frames: read
  // as far as the frames, each pushed before the frames after it.
  const bool nav_thermal = nav_run && !nav_model.thermal_json.empty();
  std::deque<TempSample> pending_temps;
  std::optional<std::int64_t> temps_read_to_ns;
  std::size_t intervals_reported = 0;
  auto last_report = Clock::now() - std::chrono::seconds(10);

  // Builds the progress of each estimator; `force`: also when little changed (at the end).
  auto report = [&](bool force) {
    const double t_s = fed_t_ns ? static_cast<double>(*fed_t_ns) / units::kNsPerS : 0.0;
    if (direct_cal && (force || direct_cal->intervals().size() != intervals_reported)) {
      intervals_reported = direct_cal->intervals().size();
      int statics = 0, rotations = 0;
      for (const auto& iv : direct_cal->intervals()) (iv.is_static ? statics : rotations) += 1;
      direct_state["statics"] = statics;
      direct_state["rotations"] = rotations;
      direct_state["program_time_s"] = t_s;
      try {
        const direct::Result r = direct_cal->finish();
        direct_state["status"] = "running";
        direct_state["estimates"] = model_estimates_json(r.model);
        direct_state["message"] = nullptr;
      } catch (const std::exception& e) {
        // Until every orientation has been seen some coefficient is undetermined; say which.
        direct_state["status"] = statics == 0 ? "waiting" : "undetermined";
        direct_state["message"] = e.what();
      }
      sink_("direct", t_s, direct_state);
    }
    if (nav_run && nav_state["status"] != "failed") {
      nav_state["status"] = fed_t_ns ? "running" : "waiting";
      nav_state["program_time_s"] = nav_t_s;
      nav_state["max_velocity_error_mps"] = nav_max_v;
      nav_state["max_position_error_m"] = nav_max_p;
      sink_("navigation", t_s, nav_state);
    }
  };

  auto feed = [&](std::int64_t upto_t_ns) {
    const std::int64_t from = fed_t_ns ? *fed_t_ns + 1 : std::numeric_limits<std::int64_t>::min();
    if (from > upto_t_ns) return;
    if (nav_thermal && (!temps_read_to_ns || upto_t_ns > *temps_read_to_ns)) {
      const std::int64_t t0 = temps_read_to_ns ? *temps_read_to_ns + 1 : std::numeric_limits<std::int64_t>::min();
      for (const TempSample& t : db->temps(t0, upto_t_ns)) pending_temps.push_back(t);
      temps_read_to_ns = upto_t_ns;
    }
    db->for_each_frame(
        [&](const ImuFrame& f) {
          if (direct_cal) direct_cal->push(f);
          if (nav_run && nav_state["status"] != "failed") {
            try {
              while (!pending_temps.empty() && pending_temps.front().t_ns <= f.t_ns) {
                nav_run->push_temp(pending_temps.front());
                pending_temps.pop_front();
              }
              nav_run->push(f);
            } catch (const std::exception& e) {
              nav_state["status"] = "failed";
              nav_state["message"] = e.what();
              sink_("navigation", static_cast<double>(f.t_ns) / units::kNsPerS, nav_state);
            }
          }
          fed_t_ns = f.t_ns;
        },
        from, upto_t_ns);
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
      if (target != std::numeric_limits<std::int64_t>::min()) feed(target);
      if (finishing) break;
      if (Clock::now() - last_report >= std::chrono::milliseconds(500)) {
        report(false);
        last_report = Clock::now();
      }
    }
    // Final results.
    Results out;
    if (direct_cal) {
      try {
        direct::Result r = direct_cal->finish();
        out.model = r.model;
        out.results["direct"] = {{"status", "done"},        {"statics", r.statics},
                                 {"rotations", r.rotations}, {"static_time_s", r.static_time_s},
                                 {"accel_residual_rms_mps2", r.accel_residual_rms_mps2},
                                 {"gyro_residual_rms_rad", r.gyro_residual_rms_rad},
                                 {"notes", r.notes}};
        direct_state["status"] = "done";
        direct_state["estimates"] = model_estimates_json(r.model);
        direct_state["message"] = nullptr;
      } catch (const std::exception& e) {
        out.results["direct"] = {{"status", "undetermined"}, {"message", e.what()}};
        direct_state["status"] = "undetermined";
        direct_state["message"] = e.what();
      }
      intervals_reported = static_cast<std::size_t>(-1);
    }
    if (nav_run) {
      if (nav_state["status"] != "failed") {
        try {
          const nav::NavSummary s = nav_run->finish();
          out.results["navigation"] = {{"status", "done"},
                                       {"duration_s", s.duration_s},
                                       {"frames", s.frames},
                                       {"max_velocity_error_mps", s.max_velocity_error_mps},
                                       {"max_position_error_m", s.max_position_error_m},
                                       {"max_attitude_error_arcsec", s.max_attitude_error_rad * units::kRadToArcsec}};
          nav_state["status"] = "done";
        } catch (const std::exception& e) {
          nav_state["status"] = "failed";
          nav_state["message"] = e.what();
        }
      }
      if (nav_state["status"] == "failed") out.results["navigation"] = {{"status", "failed"}, {"message", nav_state["message"]}};
    }
    // Final progress with the finished states (report() would recompute the direct estimate).
    const double t_s = fed_t_ns ? static_cast<double>(*fed_t_ns) / units::kNsPerS : 0.0;
    if (direct_cal) sink_("direct", t_s, direct_state);
    if (nav_run) {
      nav_state["program_time_s"] = nav_t_s;
      nav_state["max_velocity_error_mps"] = nav_max_v;
      nav_state["max_position_error_m"] = nav_max_p;
      sink_("navigation", t_s, nav_state);
    }
    std::lock_guard lock(mutex_);
    results_ = std::move(out);
  } catch (const std::exception& e) {
    spdlog::error("estimators: {}", e.what());
    std::lock_guard lock(mutex_);
    for (const auto& name : estimators_) results_.results[name] = {{"status", "failed"}, {"message", e.what()}};
  }
}

}  // namespace imucal::daemon
