// The live feed: what the operator's page follows. The latest telemetry (GET /api/live and the
// WebSocket's telemetry messages: the run's last Snapshot with the estimators' latest progress),
// and the run's transitions, events and alarms as live messages ({"type": "event", ...},
// {"type": "alarm", ...}, without seq and t) to the listener the service sets.
#pragma once

#include <functional>
#include <mutex>

#include <nlohmann/json.hpp>

#include "daemon/config/config.hpp"
#include "daemon/run/documents.hpp"

namespace imucal::daemon {

class LiveFeed final : public RunSubscriber {
 public:
  using Listener = std::function<void(const nlohmann::json&)>;
  explicit LiveFeed(const DaemonConfig& config);

  // Set before the first run starts; called on the thread that made the message, never under a
  // lock of the feed's.
  void set_listener(Listener listener) { listener_ = std::move(listener); }
  void tell(const nlohmann::json& message) const;

  nlohmann::json telemetry() const;
  nlohmann::json estimators() const;  // the active run's latest progress per estimator
  void idle();                        // no run active: "run" null, no estimators

  void transition(const Transition& transition) override;
  void event(const RunEvent& event) override;
  void snapshot(const Snapshot& snapshot) override;
  void progress(const EstimatorProgress& progress) override;

 private:
  Listener listener_;
  mutable std::mutex mutex_;
  nlohmann::json telemetry_;
  nlohmann::json estimators_ = nlohmann::json::object();
};

}  // namespace imucal::daemon
