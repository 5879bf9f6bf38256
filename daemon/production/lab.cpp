#include "daemon/production/lab.hpp"

#include <algorithm>
#include <cstdio>

#include "daemon/production/reference_equipment.hpp"

namespace imucal::daemon {

namespace {

using nlohmann::json;

// Periods a stand may miss before it shows offline (a report delayed by a busy disk or network).
constexpr std::int64_t kMissedPeriods = 3;

json run_json(const CampaignRow& row) {
  const double progress = row.duration_s > 0 ? std::clamp(row.program_time_s / row.duration_s, 0.0, 1.0) : 0.0;
  json imu = nullptr;
  if (row.imu_serial) imu = {{"serial", *row.imu_serial}, {"part_number", row.imu_part_number.value_or("")}};
  return {{"id", row.id},
          {"name", row.name},
          {"state", to_string(row.state)},
          {"program", row.program_label},
          {"progress", progress},
          {"program_time_s", row.program_time_s},
          {"duration_s", row.duration_s},
          {"imu", imu}};
}

json alarms_json(DaemonDb& db) {
  const std::vector<AlarmRow> open = db.alarms(std::nullopt, false);  // oldest first
  std::int64_t active = 0;
  json list = json::array();
  for (auto it = open.rbegin(); it != open.rend(); ++it) {
    if (!it->cleared_ms) ++active;
    if (list.size() < kStandAlarmsListed)
      list.push_back({{"id", it->id},
                      {"campaign", it->campaign_id},
                      {"campaign_name", it->campaign_name},
                      {"severity", it->severity},
                      {"message", it->message},
                      {"raised", iso8601_utc(it->raised_ms)},
                      {"active", !it->cleared_ms.has_value()},
                      {"acknowledged", it->acknowledged_ms.has_value()}});
  }
  const auto unacknowledged = std::count_if(open.begin(), open.end(), [](const AlarmRow& a) { return !a.acknowledged_ms; });
  return {{"active", active}, {"unacknowledged", unacknowledged}, {"list", list}};
}

}  // namespace

json stand_state_json(DaemonDb& db, const DaemonConfig& config, std::optional<std::int64_t> active_id,
                      std::int64_t now_ms) {
  json run = nullptr;
  if (active_id) {
    if (const auto row = db.campaign(*active_id)) run = run_json(*row);
  }
  return {{"run", run},
          {"queue", db.queue().size()},
          {"alarms", alarms_json(db)},
          {"equipment", reference_equipment_json(config, utc_day(now_ms), true)}};
}

json lab_json(const std::vector<StandRow>& stands, std::int64_t now_ms, const std::string& this_stand) {
  json out = json::array();
  for (const StandRow& s : stands) {
    // A state that does not parse (another imucal's, damaged) shows the stand without one.
    const json state = json::parse(s.state_json, nullptr, false);
    const bool readable = state.is_object();
    const std::int64_t period_ms = std::max<std::int64_t>(s.heartbeat_ms, 1);
    out.push_back({{"name", s.name},
                   {"bench", s.bench},
                   {"url", s.url},
                   {"version", s.version},
                   {"registered_at", iso8601_utc(s.registered_ms)},
                   {"last_seen", iso8601_utc(s.last_seen_ms)},
                   {"heartbeat_s", static_cast<double>(s.heartbeat_ms) / 1000.0},
                   {"online", now_ms - s.last_seen_ms <= kMissedPeriods * period_ms},
                   {"this", s.name == this_stand},
                   {"run", readable ? state.value("run", json()) : json()},
                   {"queue", readable ? state.value("queue", json(0)) : json(0)},
                   {"alarms", readable ? state.value("alarms", json()) : json()},
                   {"equipment", readable ? state.value("equipment", json()) : json()}});
  }
  return {{"stand", this_stand}, {"now", iso8601_utc(now_ms)}, {"stands", out}};
}

std::string archive_folder(const std::string& stand) {
  if (stand == ".") return "%2E";
  if (stand == "..") return "%2E%2E";
  std::string out;
  for (const char ch : stand) {
    const auto c = static_cast<unsigned char>(ch);
    const bool plain = (c >= 'A' && c <= 'Z') || (c >= 'a' && c <= 'z') || (c >= '0' && c <= '9') || c == '.' ||
                       c == '_' || c == '-';
    if (plain) {
      out.push_back(ch);
    } else {
      char hex[4];
      std::snprintf(hex, sizeof hex, "%%%02X", c);
      out += hex;
    }
  }
  return out.empty() ? std::string("%00") : out;  // an empty name has no folder of its own either
}

std::filesystem::path archived_recording(const std::string& archive_dir, const std::string& stand, std::int64_t campaign) {
  return std::filesystem::path(archive_dir) / archive_folder(stand) /
         ("campaign-" + std::to_string(campaign) + "-recording.tar");
}

json calibration_links(const std::string& stand, std::int64_t campaign, const std::string& this_stand,
                       const std::vector<StandRow>& stands, bool archived) {
  const std::string id = std::to_string(campaign);
  if (stand == this_stand)
    return {{"campaign_page", "#/campaigns/" + id}, {"recording", "/api/campaigns/" + id + "/recording"},
            {"recording_from", "this stand"}, {"note", nullptr}};
  const auto it = std::find_if(stands.begin(), stands.end(), [&](const StandRow& s) { return s.name == stand; });
  std::string url = it == stands.end() ? std::string() : it->url;
  while (!url.empty() && url.back() == '/') url.pop_back();
  json out = {{"campaign_page", url.empty() ? json(nullptr) : json(url + "/#/campaigns/" + id)}, {"note", nullptr}};
  if (archived) {
    out["recording"] = "/api/archive/" + archive_folder(stand) + "/" + id + "/recording";
    out["recording_from"] = "archive";
  } else if (!url.empty()) {
    out["recording"] = url + "/api/campaigns/" + id + "/recording";
    out["recording_from"] = "stand " + stand;
  } else {
    out["recording"] = nullptr;
    out["recording_from"] = nullptr;
    out["note"] = "stand '" + stand + "' has no address in the registry and the lab's archive does not hold the recording";
  }
  return out;
}

void add_calibration_links(json& unit_detail, const std::string& this_stand, const std::vector<StandRow>& stands,
                           const std::string& archive_dir) {
  for (json& c : unit_detail.at("calibrations")) {
    const std::string stand = c.value("stand", "");
    const auto id = c.at("campaign_id").get<std::int64_t>();
    std::error_code ec;
    const bool archived = !archive_dir.empty() && std::filesystem::exists(archived_recording(archive_dir, stand, id), ec);
    c["links"] = calibration_links(stand, id, this_stand, stands, archived);
  }
}

}  // namespace imucal::daemon
