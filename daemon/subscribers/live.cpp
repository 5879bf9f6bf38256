#include "daemon/subscribers/live.hpp"

namespace imucal::daemon {

using nlohmann::json;

// Before any run: the bench at rest, the chamber at its safe set point.
LiveFeed::LiveFeed(const DaemonConfig& config) {
  telemetry_ = {{"run", nullptr},
                {"table", {{"angle_deg", {0, 0, 0}}, {"rate_dps", {0, 0, 0}}, {"homed", false},
                           {"interlock_closed", false}, {"connected", true}, {"fault", nullptr}}},
                {"chamber", {{"temperature_C", config.chamber.safe_setpoint_C},
                             {"setpoint_C", config.chamber.safe_setpoint_C},
                             {"tolerance_C", config.chamber.tolerance_C}, {"in_band", true}, {"connected", true}}},
                {"imu", {{"frame_rate_hz", 0.0}, {"frames", 0}, {"lost_frames", 0}, {"bad_frames", 0},
                         {"connected", true}}},
                {"recorder", {{"queue_frames", 0}, {"queue_high_water_frames", 0}, {"committed_frames", 0}}},
                {"estimators", json::object()}};
}

void LiveFeed::tell(const json& message) const {
  if (listener_) listener_(message);
}

json LiveFeed::telemetry() const {
  std::lock_guard lock(mutex_);
  return telemetry_;
}

json LiveFeed::estimators() const {
  std::lock_guard lock(mutex_);
  return estimators_;
}

void LiveFeed::idle() {
  std::lock_guard lock(mutex_);
  telemetry_["run"] = nullptr;
  estimators_ = json::object();
  telemetry_["estimators"] = estimators_;
}

void LiveFeed::transition(const Transition& t) {
  tell({{"type", "event"}, {"campaign", t.campaign}, {"kind", "transition"}, {"from", to_string(t.from)},
        {"to", to_string(t.to)}, {"reason", t.reason}});
}

void LiveFeed::event(const RunEvent& e) {
  tell({{"type", "event"}, {"campaign", e.campaign}, {"kind", e.kind}, {"reason", e.reason},
        {"segment", e.segment ? json(*e.segment) : json(nullptr)},
        {"program_time_s", e.program_time_s ? json(*e.program_time_s) : json(nullptr)}});
}

void LiveFeed::snapshot(const Snapshot& s) {
  json t = s.telemetry;
  std::lock_guard lock(mutex_);
  t["estimators"] = estimators_;
  telemetry_ = std::move(t);
}

void LiveFeed::progress(const EstimatorProgress& p) {
  std::lock_guard lock(mutex_);
  estimators_[p.estimator] = p.progress;
}

}  // namespace imucal::daemon
