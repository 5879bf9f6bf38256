// The lab overview (issue 38, deliverable 2): what a stand reports with each heartbeat
// (registry/stand_heartbeat.hpp) and GET /api/lab, every stand of the registry with it. The HTTP
// layer only calls these.
#pragma once

#include <cstdint>
#include <filesystem>
#include <optional>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "daemon/config/config.hpp"
#include "daemon/db/daemon_db.hpp"

namespace imucal::daemon {

// The alarms a stand's report lists at most (the count says how many there are).
inline constexpr std::size_t kStandAlarmsListed = 10;

// A stand's state, from its database: {"run": null | {"id", "name", "state", "program", "progress"
// (0..1 of the program's time), "program_time_s", "duration_s", "imu"}, "queue": waiting
// campaigns, "alarms": {"active", "unacknowledged", "list": [newest first, at most
// kStandAlarmsListed]}, "equipment"}. `active_id`: the sequencer's active run.
// "equipment": the stand's reference equipment judged today (reference_equipment_json with its
// days: each instrument's due date, overdue or due soon, the banner), so that the lab's registry
// knows every stand's instruments and the lab page shows which is due.
nlohmann::json stand_state_json(DaemonDb& db, const DaemonConfig& config, std::optional<std::int64_t> active_id,
                                std::int64_t now_ms);

// GET /api/lab: {"stand": this stand's name, "now", "stands": [{"name", "bench", "url", "version",
// "registered_at", "last_seen", "heartbeat_s", "online", "this", "run", "queue", "alarms",
// "equipment"}]}.
// Online: seen within three heartbeat periods of `now_ms` (a stand misses two and is still so).
nlohmann::json lab_json(const std::vector<StandRow>& stands, std::int64_t now_ms, const std::string& this_stand);

// ---- The lab's shared archive of recordings (`registry.archive_dir`) -----------------------------
// Each stand writes the bundle of every run that ended with a recording there (the service, through
// subscribers/archive.hpp), so that a unit's history on any stand can fetch a recording whose
// stand is away (GET /api/archive/{stand}/{campaign}/recording).

// The folder of a stand's bundles under the archive, and the stand's segment in the archive's
// URLs: its name with every byte outside [A-Za-z0-9._-] written %XX (a stand's name is free text:
// its folder must not climb out, nor two names share one); "." and ".." are written %2E, %2E%2E.
std::string archive_folder(const std::string& stand);
// Where the archive keeps campaign `campaign` of `stand` (whether or not it is there).
std::filesystem::path archived_recording(const std::string& archive_dir, const std::string& stand, std::int64_t campaign);

// Where a calibration in a unit's history (GET /api/imus/{serial}) is shown and its recording
// fetched, from this stand's page: {"campaign_page": a link or null, "recording": a link or null,
// "recording_from": "this stand" | "archive" | "stand NAME" | null, "note": why there is no link}.
// This stand's own runs from itself; another stand's recording from the archive when `archived`,
// else from that stand's address as registered (`stands`); its page at that address.
nlohmann::json calibration_links(const std::string& stand, std::int64_t campaign, const std::string& this_stand,
                                 const std::vector<StandRow>& stands, bool archived);
// Each calibration of a unit's history (unit_registry.hpp unit_detail_json) given its "links";
// `archive_dir` empty: no archive is configured.
void add_calibration_links(nlohmann::json& unit_detail, const std::string& this_stand,
                           const std::vector<StandRow>& stands, const std::string& archive_dir);

}  // namespace imucal::daemon
