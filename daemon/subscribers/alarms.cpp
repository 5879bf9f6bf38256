#include "daemon/subscribers/alarms.hpp"

#include <algorithm>
#include <cstdio>
#include <tuple>

#include <nlohmann/json.hpp>
#include <spdlog/spdlog.h>

namespace imucal::daemon {

using nlohmann::json;

std::optional<std::string> alarm_severity_of_event(std::string_view kind) {
  if (kind == "suspended" || kind == "error") return std::string(kSeverityMajor);
  if (kind == "alarm") return std::string(kSeverityMinor);
  return std::nullopt;
}

TransitionAlarms alarms_for_transition(RunState from, RunState to, const std::string& reason) {
  TransitionAlarms out;
  const std::string change = std::string(to_string(from)) + " -> " + std::string(to_string(to)) +
                             (reason.empty() ? "" : ": " + reason);
  if (is_final(to) || to == RunState::Interrupted || from == RunState::Interrupted) {
    // The run ended (or was parked, or is taken up again): nothing of it is still going on.
    out.clear_all = true;
    out.clear_reason = change;
    out.raise_interrupted = to == RunState::Interrupted;
  } else if (to == RunState::Running) {
    // Running again: whatever held it has cleared (also after a pause taken while suspended).
    out.clear_source = "suspended";
    out.clear_reason = change;
  }
  return out;
}

namespace {

json opt_time(const std::optional<std::int64_t>& ms) { return ms ? json(iso8601_utc(*ms)) : json(nullptr); }

std::string program_time_text(const std::optional<double>& t_s) {
  if (!t_s) return {};
  char buf[40];
  std::snprintf(buf, sizeof buf, "%.3f", *t_s);
  return buf;
}

}  // namespace

json alarm_json(const AlarmRow& a) {
  return {{"id", a.id},
          {"campaign", a.campaign_id},
          {"campaign_name", a.campaign_name},
          {"severity", a.severity},
          {"source", a.source},
          {"message", a.message},
          {"segment", a.segment ? json(*a.segment) : json(nullptr)},
          {"program_time_s", a.program_time_s ? json(*a.program_time_s) : json(nullptr)},
          {"raised", iso8601_utc(a.raised_ms)},
          {"cleared", opt_time(a.cleared_ms)},
          {"cleared_reason", a.cleared_reason ? json(*a.cleared_reason) : json(nullptr)},
          {"active", !a.cleared_ms.has_value()},
          {"acknowledged_by", a.acknowledged_by ? json(*a.acknowledged_by) : json(nullptr)},
          {"acknowledged", opt_time(a.acknowledged_ms)}};
}

json alarm_message(const std::string& change, const AlarmRow& alarm) {
  return {{"type", "alarm"}, {"change", change}, {"alarm", alarm_json(alarm)}};
}

std::vector<json> apply_transition_alarms(DaemonDb& db, std::int64_t campaign_id, RunState from, RunState to,
                                          const std::string& reason) {
  const TransitionAlarms what = alarms_for_transition(from, to, reason);
  std::vector<json> messages;
  if (what.clear_all || what.clear_source)
    for (const AlarmRow& a : db.clear_alarms(campaign_id, what.clear_source, what.clear_reason))
      messages.push_back(alarm_message("cleared", a));
  if (what.raise_interrupted)
    messages.push_back(alarm_message(
        "raised", db.raise_alarm(campaign_id, kSeverityMajor, "interrupted", "the run was interrupted: " + reason,
                                 std::nullopt, std::nullopt)));
  return messages;
}

std::string run_log_csv(const std::vector<TransitionRow>& transitions, const std::vector<EventRow>& events,
                        const std::vector<AlarmRow>& alarms) {
  // (time, order of the record kinds at the same instant, position) -> the row's fields.
  struct Line {
    std::int64_t t_ms;
    int record_order;
    std::size_t index;
    std::vector<std::string> fields;
  };
  std::vector<Line> lines;
  const auto opt_iso = [](const std::optional<std::int64_t>& ms) { return ms ? iso8601_utc(*ms) : std::string(); };
  for (std::size_t i = 0; i < transitions.size(); ++i) {
    const TransitionRow& t = transitions[i];
    const std::string kind = (t.from ? std::string(to_string(*t.from)) : std::string("(new)")) + " -> " +
                             std::string(to_string(t.to));
    lines.push_back({t.t_ms, 0, i, {iso8601_utc(t.t_ms), "transition", kind, "", "", "", t.reason, "", "", "", "", "", ""}});
  }
  for (std::size_t i = 0; i < events.size(); ++i) {
    const EventRow& e = events[i];
    lines.push_back({e.t_ms, 1, i,
                     {iso8601_utc(e.t_ms), "event", e.kind, alarm_severity_of_event(e.kind).value_or(""),
                      e.segment ? std::to_string(*e.segment) : "", program_time_text(e.program_time_s), e.reason, "",
                      "", "", "", "", ""}});
  }
  for (std::size_t i = 0; i < alarms.size(); ++i) {
    const AlarmRow& a = alarms[i];
    lines.push_back({a.raised_ms, 2, i,
                     {iso8601_utc(a.raised_ms), "alarm", a.source, a.severity, a.segment ? std::to_string(*a.segment) : "",
                      program_time_text(a.program_time_s), a.message, std::to_string(a.id), iso8601_utc(a.raised_ms),
                      opt_iso(a.cleared_ms), a.cleared_reason.value_or(""), a.acknowledged_by.value_or(""),
                      opt_iso(a.acknowledged_ms)}});
  }
  std::stable_sort(lines.begin(), lines.end(), [](const Line& a, const Line& b) {
    return std::tie(a.t_ms, a.record_order, a.index) < std::tie(b.t_ms, b.record_order, b.index);
  });
  std::string out =
      "time,record,kind,severity,segment,program_time_s,message,alarm_id,raised,cleared,cleared_reason,"
      "acknowledged_by,acknowledged\r\n";
  for (const Line& l : lines) {
    for (std::size_t k = 0; k < l.fields.size(); ++k) {
      if (k > 0) out += ',';
      out += csv_field(l.fields[k]);
    }
    out += "\r\n";
  }
  return out;
}

void AlarmsSubscriber::transition(const Transition& t) {
  try {
    writes_.write("the alarms of campaign " + std::to_string(t.campaign) + "'s " + std::string(to_string(t.from)) +
                      " -> " + std::string(to_string(t.to)),
                  [this, t] {
                    for (const nlohmann::json& message : apply_transition_alarms(db_, t.campaign, t.from, t.to, t.reason))
                      tell_(message);
                  });
  } catch (const std::exception& e) {
    spdlog::error("campaign {}: alarms of {} -> {} not stored: {}", t.campaign, to_string(t.from), to_string(t.to),
                  e.what());
  }
}

void AlarmsSubscriber::event(const RunEvent& e) {
  const auto severity = alarm_severity_of_event(e.kind);
  if (!severity) return;
  try {
    writes_.write("campaign " + std::to_string(e.campaign) + "'s alarm '" + e.reason + "'",
                  [this, severity = *severity, e] {
                    tell_(alarm_message("raised", db_.raise_alarm(e.campaign, severity, e.kind, e.reason, e.segment,
                                                                  e.program_time_s)));
                  });
  } catch (const std::exception& failure) {
    spdlog::error("campaign {}: alarm '{}' not stored: {}", e.campaign, e.reason, failure.what());
  }
}

}  // namespace imucal::daemon
