#include "daemon/subscribers/service_db.hpp"

#include <string>

#include <spdlog/spdlog.h>

namespace imucal::daemon {

namespace {
std::string of(std::int64_t campaign, const std::string& what) {
  return "campaign " + std::to_string(campaign) + "'s " + what;
}
}  // namespace

void ServiceDbSubscriber::start(const RunStart& start) {
  {
    std::lock_guard lock(estimators_mutex_);
    estimators_ = nlohmann::json::object();
  }
  if (!start.resuming)
    writes_.write(of(start.campaign, "run file"),
                  [this, id = start.campaign, relative = start.run_file_relative] { db_.set_run_db(id, relative); });
}

void ServiceDbSubscriber::transition(const Transition& t) {
  if (t.stored) return;  // a campaign not running: the sequencer changed it in the database
  // The sequencer's state is the truth meanwhile; the database follows in order. A change the
  // database refuses when it is stored at last is in the log.
  const std::string what = "campaign " + std::to_string(t.campaign) + " -> " + std::string(to_string(t.to));
  writes_.write_now_or_later(
      what, [&] { return db_.set_state(t.campaign, t.to, t.reason); },
      [this, id = t.campaign, to = t.to, reason = t.reason] {
        if (!db_.set_state(id, to, reason))
          spdlog::error("daemon database: campaign {} -> {} refused when stored late", id, to_string(to));
      });
}

void ServiceDbSubscriber::event(const RunEvent& e) {
  // An event that cannot be stored must not stop the run that made it: it is in the log.
  try {
    writes_.write(of(e.campaign, "event '" + e.kind + "'"), [this, e] {
      db_.add_event(e.campaign, e.kind, e.segment, e.program_time_s, e.reason);
    });
  } catch (const std::exception& failure) {
    spdlog::error("campaign {}: event '{}' not stored: {}", e.campaign, e.reason, failure.what());
  }
}

void ServiceDbSubscriber::checkpoint(const Checkpoint& c) {
  writes_.write(of(c.campaign, "checkpoint"), [this, c] { db_.set_checkpoint(c.campaign, c.segment, c.t_s); });
}

// The run's counters once a second (and at every moment that must be seen); with a full disk they
// wait for the next second, and what was deferred is tried again.
void ServiceDbSubscriber::snapshot(const Snapshot& s) {
  const auto now = std::chrono::steady_clock::now();
  if (!s.force && now - last_counters_ < std::chrono::seconds(1)) return;
  last_counters_ = now;
  if (!writes_.retry()) return;
  try {
    db_.update_run(s.campaign, s.counters.program_time_s, s.counters.frames, s.counters.lost, s.counters.bad);
  } catch (const std::exception& e) {
    if (!is_database_failure(e)) throw;
    spdlog::warn("campaign {}: counters not stored: {}", s.campaign, e.what());
  }
}

// The estimators' worker thread: stored at once, not deferred (the next one says more).
void ServiceDbSubscriber::progress(const EstimatorProgress& p) {
  nlohmann::json all;
  {
    std::lock_guard lock(estimators_mutex_);
    estimators_[p.estimator] = p.progress;
    all = estimators_;
  }
  try {
    db_.add_progress(p.campaign, p.estimator, p.program_time_s, p.progress.dump());
    db_.set_estimators(p.campaign, all.dump());
  } catch (const std::exception& e) {
    spdlog::error("campaign {}: cannot store estimator progress: {}", p.campaign, e.what());
  }
}

void ServiceDbSubscriber::results(const RunResults& r) {
  if (r.model_json)
    writes_.write(of(r.campaign, "model"), [this, id = r.campaign, text = *r.model_json] { db_.set_model(id, text); });
  writes_.write(of(r.campaign, "results"), [this, id = r.campaign, text = r.results.dump()] { db_.set_results(id, text); });
}

void ServiceDbSubscriber::error(const RunError& e) {
  writes_.write(of(e.campaign, "error"), [this, id = e.campaign, why = e.why] { db_.set_error(id, why); });
}

void ServiceDbSubscriber::stop(const RunStop& s) {
  writes_.write(of(s.campaign, "counters"), [this, id = s.campaign, c = s.counters] {
    db_.update_run(id, c.program_time_s, c.frames, c.lost, c.bad);
  });
  if (s.complete)
    writes_.write(of(s.campaign, "completeness"),
                  [this, id = s.campaign, complete = *s.complete] { db_.set_complete(id, complete); });
}

}  // namespace imucal::daemon
