#include "daemon/production/unit_registry.hpp"

#include <algorithm>
#include <cstdio>
#include <map>
#include <optional>

#include "core/number_text.hpp"
#include "daemon/db/csv.hpp"
#include "daemon/production/acceptance.hpp"

namespace imucal::daemon {

using nlohmann::json;

namespace {

bool ended(const CampaignRow& row) { return is_final(row.state); }

json model_or_null(const CampaignRow& row) {
  if (!row.model_json) return nullptr;
  json m = json::parse(*row.model_json, nullptr, false);
  return m.is_discarded() ? json(nullptr) : m;
}

// 17 digits round-trip: the CSV agrees with the model exactly.
std::string exact_text(double v) { return number_text(v, 17); }

}  // namespace

bool counts_as_calibration(const CampaignRow& row) {
  return ended(row) && row.model_json.has_value() && (row.complete.value_or(false) || row.accepted_reason.has_value());
}

std::string cannot_accept(const CampaignRow& row) {
  if (!ended(row)) return "it has not ended (state " + std::string(to_string(row.state)) + ")";
  if (row.complete.value_or(false)) return "it is complete: it counts without acceptance";
  if (!row.model_json) return "it has no model";
  return {};
}

json completeness_json(const CampaignRow& row) {
  json accepted = nullptr;
  if (row.accepted_reason)
    accepted = {{"reason", *row.accepted_reason},
                {"by", row.accepted_by.value_or("")},
                {"t", row.accepted_ms ? json(iso8601_utc(*row.accepted_ms)) : json(nullptr)}};
  return {{"complete", row.complete.value_or(false)}, {"accepted", accepted}, {"counts", counts_as_calibration(row)}};
}

json run_verdict(const CampaignRow& row, const AcceptanceLimits& limits) {
  if (!ended(row)) return nullptr;
  return verdict_or_null(model_or_null(row), row.imu_part_number.value_or(""), limits);
}

namespace {

// What the list says of one unit: its campaigns, its calibrations and the last of them.
struct UnitTally {
  std::string part_number;
  std::int64_t campaigns = 0, calibrations = 0;
  const CampaignRow* last = nullptr;
};

json unit_entry_json(const std::string& serial, const UnitTally& u, const AcceptanceLimits& limits) {
  json last = nullptr, pass = nullptr;
  if (u.last) {
    const json verdict = run_verdict(*u.last, limits);
    if (!verdict.is_null()) pass = verdict.at("pass");
    last = {{"campaign_id", u.last->id},
            {"stand", u.last->stand},
            {"program", u.last->program_label},
            {"date", iso8601_utc(u.last->ended_ms.value_or(u.last->created_ms))},
            {"verdict", verdict}};
  }
  // The unit passes or fails by its last calibration (null: no limits for it, or none yet).
  return {{"serial", serial},
          {"part_number", u.part_number},
          {"campaigns", u.campaigns},
          {"calibrations", u.calibrations},
          {"last_calibration", last},
          {"pass", pass}};
}

}  // namespace

json unit_list_json(const std::vector<CampaignRow>& rows, const AcceptanceLimits& limits) {
  std::map<std::string, UnitTally> units;
  for (const CampaignRow& row : rows) {
    if (!row.imu_serial) continue;  // a campaign that names no unit (DaemonDb::unit_campaigns gives none)
    UnitTally& u = units[*row.imu_serial];
    ++u.campaigns;
    // The part number the unit was last named with (a unit keeps its part number; a typo fixed
    // in a later campaign wins).
    if (row.imu_part_number && !row.imu_part_number->empty()) u.part_number = *row.imu_part_number;
    if (counts_as_calibration(row)) {
      ++u.calibrations;
      u.last = &row;
    }
  }
  json list = json::array();
  for (const auto& [serial, u] : units) list.push_back(unit_entry_json(serial, u, limits));
  return {{"imus", list}};
}

json unit_detail_json(const std::string& serial, const std::vector<CampaignRow>& rows,
                      const AcceptanceLimits& limits) {
  json calibrations = json::array(), pending = json::array();
  std::string part_number;
  std::int64_t counted = 0;
  std::vector<json> counted_models;
  const CampaignRow* previous = nullptr;  // the previous calibration that counts
  for (const CampaignRow& row : rows) {
    if (row.imu_part_number && !row.imu_part_number->empty()) part_number = *row.imu_part_number;
    if (!ended(row)) {
      pending.push_back({{"campaign_id", row.id}, {"stand", row.stand}, {"state", to_string(row.state)}});
      continue;
    }
    json c = {{"campaign_id", row.id},
              {"stand", row.stand},
              {"name", row.name},
              {"program", row.program_label},
              {"state", to_string(row.state)},
              {"date", iso8601_utc(row.ended_ms.value_or(row.created_ms))},
              {"progress", row.duration_s > 0 ? std::clamp(row.program_time_s / row.duration_s, 0.0, 1.0) : 0.0},
              {"verdict", run_verdict(row, limits)},
              {"model", model_or_null(row)}};
    c.update(completeness_json(row));
    // The change since the previous calibration in combined sigmas, for every run with a model
    // (a partial one too: an operator deciding whether to accept it wants to see it).
    json change = nullptr;
    if (previous && !c.at("model").is_null()) {
      const json cmp = compare_json(model_or_null(*previous), c.at("model"));
      json in_sigmas = json::object();
      std::vector<std::string> significant;
      for (const json& r : cmp.at("coefficients")) {
        if (r.at("in_sigmas").is_null()) continue;
        in_sigmas[r.at("key").get<std::string>()] = r.at("in_sigmas");
        if (r.at("significant").get<bool>()) significant.push_back(r.at("key").get<std::string>());
      }
      change = {{"since_campaign_id", previous->id},
                {"since_stand", previous->stand},
                {"in_sigmas", in_sigmas},
                {"significant", significant}};
    }
    c["change"] = change;
    if (c.at("counts").get<bool>()) {
      ++counted;
      counted_models.push_back(c.at("model"));
      previous = &row;
    }
    calibrations.push_back(std::move(c));
  }
  return {{"serial", serial},
          {"part_number", part_number},
          {"limits", limits.parts.count(part_number) ? json(limits.source) : json(nullptr)},
          {"calibrations_counted", counted},
          {"calibrations", calibrations},
          {"repeatability", repeatability_json(counted_models)},
          {"not_ended", pending}};
}

std::string unit_history_csv(const std::vector<CampaignRow>& rows) {
  struct Line {
    const CampaignRow* row;
    std::map<std::string, double> values, sigmas;
  };
  std::vector<Line> lines;
  std::vector<std::string> columns;  // in the order the models first name them
  for (const CampaignRow& row : rows) {
    if (!ended(row)) continue;
    const json model = model_or_null(row);
    if (model.is_null()) continue;
    Line line{&row, {}, {}};
    for (const auto& [name, v] : flat_coefficients(model)) {
      if (std::find(columns.begin(), columns.end(), name) == columns.end()) columns.push_back(name);
      line.values[name] = v;
    }
    if (model.contains("sigma"))
      for (const auto& [name, v] : flat_coefficients(model.at("sigma"))) line.sigmas[name] = v;
    lines.push_back(std::move(line));
  }
  std::string out = "campaign_id,stand,name,program,date,state,complete,counts";
  for (const auto& c : columns) out += "," + csv_field(c) + "," + csv_field(c + ".sigma");
  out += "\n";
  for (const Line& l : lines) {
    const CampaignRow& r = *l.row;
    out += std::to_string(r.id) + "," + csv_field(r.stand) + "," + csv_field(r.name) + "," + csv_field(r.program_label) + "," +
           iso8601_utc(r.ended_ms.value_or(r.created_ms)) + "," + std::string(to_string(r.state)) + "," +
           (r.complete.value_or(false) ? "true" : "false") + "," + (counts_as_calibration(r) ? "true" : "false");
    for (const auto& c : columns) {
      const auto v = l.values.find(c);
      const auto s = l.sigmas.find(c);
      out += "," + (v != l.values.end() ? exact_text(v->second) : std::string());
      out += "," + (s != l.sigmas.end() ? exact_text(s->second) : std::string());
    }
    out += "\n";
  }
  return out;
}

}  // namespace imucal::daemon
