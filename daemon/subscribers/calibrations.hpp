// The units' calibrations' subscriber (issue 38): after each transition of a run, the campaign's
// row is recorded in the registry (registry.hpp record_calibration), so that the lab's registry
// shows every stand's runs of a unit with their state, and at the end with the model, the
// completeness and the verdict's inputs. The recording is handed in as a function: it lives in the
// registry, which the subscribers do not reach (docs/ARCHITECTURE.md).
//
// Subscribed by the service after the sequencer's own subscribers: the service database has
// stored the transition (and, at the end, the model and the completeness, which come before the
// last transition) when the row is read. Called on the thread that made the change; it changes no
// run's state and never throws.
#pragma once

#include <cstdint>
#include <functional>

#include "daemon/run/documents.hpp"

namespace imucal::daemon {

class CalibrationsSubscriber final : public RunSubscriber {
 public:
  // record_unit_calibration of the campaign (registry/calibrations.hpp); may throw.
  using Record = std::function<void(std::int64_t campaign)>;

  explicit CalibrationsSubscriber(Record record) : record_(std::move(record)) {}

  void transition(const Transition& transition) override;

 private:
  Record record_;
};

}  // namespace imucal::daemon
