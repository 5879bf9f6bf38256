#include "daemon/production/reference_equipment.hpp"

#include <cstdio>

#include "core/earth.hpp"

namespace imucal::daemon {

using nlohmann::json;

namespace {

constexpr std::int64_t kDayMs = 86'400'000;

// The rule, on one instrument's due date (checked to be a date when the configuration was read).
InstrumentDue judged(std::string instrument, std::string title, std::string identity, std::string serial,
                     std::string certificate, const std::string& due, std::int64_t day) {
  InstrumentDue out{std::move(instrument), std::move(title), std::move(identity), std::move(serial),
                    std::move(certificate), due};
  // A due date that is no date (only a configuration made in code can have one) counts as past.
  out.due_in_days = date_day_number(due).value_or(day - 1) - day;
  out.overdue = out.due_in_days < 0;
  out.due_soon = !out.overdue && out.due_in_days <= kDueSoonDays;
  return out;
}

InstrumentDue judged(const char* key, const char* title, const ReferenceInstrument& i, std::int64_t day) {
  return judged(key, title, i.make + " " + i.model + ", serial " + i.serial, i.serial, i.calibration_certificate,
                i.calibration_due, day);
}

json text_or_null(const std::string& text) { return text.empty() ? json(nullptr) : json(text); }

const InstrumentDue* find_instrument(const std::vector<InstrumentDue>& judged_list, const std::string& key) {
  for (const InstrumentDue& d : judged_list)
    if (d.instrument == key) return &d;
  return nullptr;
}

void add_due(json& out, const InstrumentDue& d, bool with_days) {
  out["overdue"] = d.overdue;
  if (!with_days) return;
  out["due_in_days"] = d.due_in_days;
  out["due_soon"] = d.due_soon;
  out["text"] = due_line(d);
}

std::string days(std::int64_t n) { return std::to_string(n) + (n == 1 ? " day" : " days"); }

json instrument_json(const ReferenceInstrument& i, const InstrumentDue& d, bool with_days) {
  json out = {{"make", i.make},
              {"model", i.model},
              {"serial", i.serial},
              {"calibration_due", i.calibration_due},
              {"calibration_certificate", text_or_null(i.calibration_certificate)},
              {"uncertainty", text_or_null(i.uncertainty)}};
  add_due(out, d, with_days);
  return out;
}

}  // namespace

std::int64_t utc_day(std::int64_t unix_ms) { return unix_ms >= 0 ? unix_ms / kDayMs : (unix_ms - (kDayMs - 1)) / kDayMs; }

std::vector<InstrumentDue> equipment_due(const ReferenceEquipment& equipment, std::int64_t day) {
  std::vector<InstrumentDue> out;
  if (equipment.table) out.push_back(judged("table", "rate table", *equipment.table, day));
  if (equipment.chamber) out.push_back(judged("chamber", "climatic chamber", *equipment.chamber, day));
  if (const auto& g = equipment.gravity) {
    out.push_back(judged("gravity", "gravity survey", "by " + g->surveyed_by + ", certificate " + g->calibration_certificate,
                         "", g->calibration_certificate, g->calibration_due, day));
  }
  return out;
}

std::string due_sentence(const InstrumentDue& d) {
  return "the " + d.title + " (" + d.identity + ") " + (d.overdue ? "was" : "is") + " due for " +
         (d.instrument == "gravity" ? "a new survey" : "calibration") + " on " + d.calibration_due;
}

std::string due_line(const InstrumentDue& d) {
  std::string out = due_sentence(d);
  out[0] = 'T';
  const std::int64_t n = d.due_in_days;
  if (d.overdue) return out + " (" + days(-n) + " ago).";
  return out + " (" + (n == 0 ? "today" : n == 1 ? "tomorrow" : "in " + days(n)) + ").";
}

std::string due_banner(const std::vector<InstrumentDue>& judged_list) {
  bool overdue = false, soon = false;
  for (const InstrumentDue& d : judged_list) {
    overdue = overdue || d.overdue;
    soon = soon || d.due_soon;
  }
  if (overdue)
    return "A campaign starts only when an operator overrides this with a reason, which the audit trail keeps and "
           "the run's certificate states.";
  if (soon) return "After its due date no campaign starts without an operator's override.";
  return {};
}

std::string overdue_text(const std::vector<InstrumentDue>& judged_list) {
  std::string out;
  for (const InstrumentDue& d : judged_list)
    if (d.overdue) out += (out.empty() ? "" : "; ") + due_sentence(d);
  return out;
}

json reference_equipment_json(const DaemonConfig& config, std::int64_t day, bool with_days) {
  const ReferenceEquipment& e = config.reference_equipment;
  const std::vector<InstrumentDue> judged_list = equipment_due(e, day);
  json out = {{"table", nullptr}, {"chamber", nullptr}, {"gravity", nullptr}};
  if (const InstrumentDue* d = find_instrument(judged_list, "table"); e.table && d != nullptr)
    out["table"] = instrument_json(*e.table, *d, with_days);
  if (const InstrumentDue* d = find_instrument(judged_list, "chamber"); e.chamber && d != nullptr)
    out["chamber"] = instrument_json(*e.chamber, *d, with_days);
  const InstrumentDue* d = find_instrument(judged_list, "gravity");
  if (e.gravity && d != nullptr) {
    const double sigma = earth::site_gravity_sigma_mps2(config.site);
    char text[64];
    std::snprintf(text, sizeof text, "%g m/s^2 (1 sigma)", sigma);
    json j = {{"surveyed_by", e.gravity->surveyed_by},
              {"calibration_certificate", e.gravity->calibration_certificate},
              {"calibration_due", e.gravity->calibration_due},
              {"uncertainty", text},
              {"sigma_mps2", sigma}};
    add_due(j, *d, with_days);
    out["gravity"] = std::move(j);
  }
  if (with_days) {
    const std::string banner = due_banner(judged_list);
    out["banner"] = banner.empty() ? json(nullptr) : json(banner);
  }
  return out;
}

}  // namespace imucal::daemon
