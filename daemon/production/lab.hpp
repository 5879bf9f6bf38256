// The lab overview (issue 38, deliverable 2): what a stand reports with each heartbeat
// (registry/stand_heartbeat.hpp) and GET /api/lab, every stand of the registry with it. The HTTP
// layer only calls these.
#pragma once

#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "daemon/db/daemon_db.hpp"

namespace imucal::daemon {

// The alarms a stand's report lists at most (the count says how many there are).
inline constexpr std::size_t kStandAlarmsListed = 10;

// A stand's state, from its database: {"run": null | {"id", "name", "state", "program", "progress"
// (0..1 of the program's time), "program_time_s", "duration_s", "imu"}, "queue": waiting
// campaigns, "alarms": {"active", "unacknowledged", "list": [newest first, at most
// kStandAlarmsListed]}}. `active_id`: the sequencer's active run.
nlohmann::json stand_state_json(DaemonDb& db, std::optional<std::int64_t> active_id);

// GET /api/lab: {"stand": this stand's name, "now", "stands": [{"name", "bench", "url", "version",
// "registered_at", "last_seen", "heartbeat_s", "online", "this", "run", "queue", "alarms"}]}.
// Online: seen within three heartbeat periods of `now_ms` (a stand misses two and is still so).
nlohmann::json lab_json(const std::vector<StandRow>& stands, std::int64_t now_ms, const std::string& this_stand);

}  // namespace imucal::daemon
