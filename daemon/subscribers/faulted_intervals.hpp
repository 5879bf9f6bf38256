// The intervals in which a run's recording was held by a fault, from the run's stored history:
// each suspension (a suspender tripped: a device fault, a full disk) and each interruption (the
// daemon shut down, or was found dead at start-up after a crash). The sequencer keeps them in the
// run file (storage::kFaultedIntervalsKey), and the exported bundle's meta.json lists them
// (docs/storage.md). A pause is an operator's and is not listed.
#pragma once

#include <vector>

#include <nlohmann/json.hpp>

#include "daemon/db/daemon_db.hpp"

namespace imucal::daemon {

// One object per interval, oldest first: {"state": "suspended"|"interrupted", "reason",
// "start", "end" (ISO 8601 UTC; end null while the run is in it), "program_time_s"} (null when
// the history does not place it).
nlohmann::json faulted_intervals(const std::vector<TransitionRow>& transitions, const std::vector<EventRow>& events);

}  // namespace imucal::daemon
