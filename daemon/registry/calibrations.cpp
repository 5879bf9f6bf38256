#include "daemon/registry/calibrations.hpp"

#include <stdexcept>

#include <nlohmann/json.hpp>

namespace imucal::daemon {

using nlohmann::json;

namespace {

template <class T>
json optional_json(const std::optional<T>& value) {
  return value ? json(*value) : json(nullptr);
}

template <class T>
std::optional<T> optional_from(const json& j, const char* key) {
  if (!j.contains(key) || j.at(key).is_null()) return std::nullopt;
  return j.at(key).get<T>();
}

template <class T>
T required(const json& j, const char* key) {
  if (!j.contains(key)) throw std::invalid_argument(std::string("a recorded calibration has no '") + key + "'");
  return j.at(key).get<T>();
}

}  // namespace

std::string campaign_row_json(const CampaignRow& r) {
  return json{{"id", r.id},
              {"name", r.name},
              {"spec_json", r.spec_json},
              {"program_label", r.program_label},
              {"duration_s", r.duration_s},
              {"state", std::string(to_string(r.state))},
              {"created_ms", r.created_ms},
              {"started_ms", optional_json(r.started_ms)},
              {"ended_ms", optional_json(r.ended_ms)},
              {"program_time_s", r.program_time_s},
              {"frames", r.frames},
              {"lost_frames", r.lost_frames},
              {"bad_frames", r.bad_frames},
              {"run_db", r.run_db},
              {"model_json", optional_json(r.model_json)},
              {"results_json", optional_json(r.results_json)},
              {"error", optional_json(r.error)},
              {"imu_serial", optional_json(r.imu_serial)},
              {"imu_part_number", optional_json(r.imu_part_number)},
              {"complete", optional_json(r.complete)},
              {"accepted_reason", optional_json(r.accepted_reason)},
              {"accepted_by", optional_json(r.accepted_by)},
              {"accepted_ms", optional_json(r.accepted_ms)}}
      .dump();
}

CampaignRow campaign_row_from_json(const std::string& text) {
  const json j = json::parse(text, nullptr, false);
  if (!j.is_object()) throw std::invalid_argument("a recorded calibration is not a JSON object");
  CampaignRow r;
  r.id = required<std::int64_t>(j, "id");
  r.name = required<std::string>(j, "name");
  r.spec_json = required<std::string>(j, "spec_json");
  r.program_label = required<std::string>(j, "program_label");
  r.duration_s = required<double>(j, "duration_s");
  const std::string state = required<std::string>(j, "state");
  const auto parsed = parse_run_state(state);
  if (!parsed) throw std::invalid_argument("a recorded calibration has the unknown state '" + state + "'");
  r.state = *parsed;
  r.created_ms = required<std::int64_t>(j, "created_ms");
  r.started_ms = optional_from<std::int64_t>(j, "started_ms");
  r.ended_ms = optional_from<std::int64_t>(j, "ended_ms");
  r.program_time_s = required<double>(j, "program_time_s");
  r.frames = required<std::int64_t>(j, "frames");
  r.lost_frames = required<std::int64_t>(j, "lost_frames");
  r.bad_frames = required<std::int64_t>(j, "bad_frames");
  r.run_db = required<std::string>(j, "run_db");
  r.model_json = optional_from<std::string>(j, "model_json");
  r.results_json = optional_from<std::string>(j, "results_json");
  r.error = optional_from<std::string>(j, "error");
  r.imu_serial = optional_from<std::string>(j, "imu_serial");
  r.imu_part_number = optional_from<std::string>(j, "imu_part_number");
  r.complete = optional_from<bool>(j, "complete");
  r.accepted_reason = optional_from<std::string>(j, "accepted_reason");
  r.accepted_by = optional_from<std::string>(j, "accepted_by");
  r.accepted_ms = optional_from<std::int64_t>(j, "accepted_ms");
  return r;
}

bool record_unit_calibration(DaemonDb& db, Registry& registry, std::int64_t campaign_id) {
  const auto row = db.campaign(campaign_id);
  if (!row || !row->imu_serial) return false;
  registry.record_calibration(*row);
  return true;
}

}  // namespace imucal::daemon
