// Alarms an operator acknowledges (issue 18, docs/api.md "Alarms"): which of a run's events and
// state changes raise an alarm, how serious it is, what clears it, and the run's log as CSV. Pure
// functions of the rows; their subscriber (AlarmsSubscriber, below) stores and broadcasts what they
// decide for a run's documents, the API serves them (api.cpp).
//
// Severities, a small fixed set:
//   major  the run was held, failed or interrupted (a suspension, an error, an interruption);
//   minor  a device or the recorder reported a problem the run went on through (`alarm` events).
// An alarm is active until its condition ends: a suspension's when the run runs again, every
// other one when its run ends (or leaves `interrupted`). Active or not, it stays listed until an
// operator has acknowledged it.
#pragma once

#include <functional>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include <nlohmann/json_fwd.hpp>

#include "daemon/db/csv.hpp"
#include "daemon/db/daemon_db.hpp"
#include "daemon/db/run_state.hpp"
#include "daemon/db/write_queue.hpp"
#include "daemon/run/documents.hpp"

namespace imucal::daemon {

inline constexpr const char* kSeverityMajor = "major";
inline constexpr const char* kSeverityMinor = "minor";

// The severity of the alarm a run event of this kind raises, or nothing (info, redo, resumed,
// paused, homed, ...).
std::optional<std::string> alarm_severity_of_event(std::string_view kind);

// What a state change of a run does to its alarms (applied in this order: clear, then raise).
struct TransitionAlarms {
  bool clear_all = false;                  // the run ended, or left `interrupted`
  std::optional<std::string> clear_source;  // only the alarms of this source (a suspension's)
  std::string clear_reason;                // kept with each alarm cleared
  bool raise_interrupted = false;          // a major alarm: the run was interrupted
};
TransitionAlarms alarms_for_transition(RunState from, RunState to, const std::string& reason);

// Applies alarms_for_transition to the database: clears, then raises. Returns the changes as live
// messages ({"type": "alarm", "change": "cleared" | "raised", "alarm": alarm_json}).
std::vector<nlohmann::json> apply_transition_alarms(DaemonDb& db, std::int64_t campaign_id, RunState from, RunState to,
                                                    const std::string& reason);

// {"type": "alarm", "change": change, "alarm": alarm_json(alarm)}: what the live WebSocket carries.
nlohmann::json alarm_message(const std::string& change, const AlarmRow& alarm);

// {"id", "campaign", "campaign_name", "severity", "source", "message", "segment", "program_time_s",
//  "raised", "cleared", "cleared_reason", "active", "acknowledged_by", "acknowledged"}; times in
// ISO 8601 UTC, null when not (yet) so.
nlohmann::json alarm_json(const AlarmRow& alarm);


// GET /api/campaigns/{id}/events.csv: the run's transitions, events and alarms in time order, one
// row each, RFC 4180 (CRLF line ends, a header row). Columns: time, record (transition, event,
// alarm), kind, severity, segment, program_time_s, message, alarm_id, raised, cleared,
// cleared_reason, acknowledged_by, acknowledged (the last six for alarms only).
std::string run_log_csv(const std::vector<TransitionRow>& transitions, const std::vector<EventRow>& events,
                        const std::vector<AlarmRow>& alarms);

// A run's alarms from its documents: a serious event raises one, a state change clears and raises
// what it implies; each change stored (through the WriteQueue: with a full disk, shown once the
// disk takes it again; the event and the run's state say it meanwhile) and then told to the live
// view through `tell`. An alarm that cannot be stored does not stop the run: it is in the log.
class AlarmsSubscriber final : public RunSubscriber {
 public:
  using Tell = std::function<void(const nlohmann::json&)>;
  AlarmsSubscriber(DaemonDb& db, WriteQueue& writes, Tell tell) : db_(db), writes_(writes), tell_(std::move(tell)) {}
  void transition(const Transition& transition) override;
  void event(const RunEvent& event) override;

 private:
  DaemonDb& db_;
  WriteQueue& writes_;
  Tell tell_;
};

}  // namespace imucal::daemon
