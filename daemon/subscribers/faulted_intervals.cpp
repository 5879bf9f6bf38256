#include "daemon/subscribers/faulted_intervals.hpp"

#include <cstdint>
#include <limits>
#include <optional>

namespace imucal::daemon {

namespace {

using nlohmann::json;

bool is_fault(RunState state) { return state == RunState::Suspended || state == RunState::Interrupted; }

// Where an interval lies on the program's time axis, from the event that placed it: a suspension's
// own event (the program time at which it tripped), or the redo that resumed an interruption (the
// last frame committed before it, from which the run went on). The first such event from the
// interval's start until the next interval's.
std::optional<double> program_time_of(RunState state, const std::vector<EventRow>& events, std::int64_t from_ms,
                                      std::int64_t until_ms) {
  const char* kind = state == RunState::Suspended ? "suspended" : "redo";
  for (const EventRow& e : events)
    if (e.kind == kind && e.t_ms >= from_ms && e.t_ms < until_ms) return e.program_time_s;
  return std::nullopt;
}

}  // namespace

json faulted_intervals(const std::vector<TransitionRow>& transitions, const std::vector<EventRow>& events) {
  json out = json::array();
  for (std::size_t i = 0; i < transitions.size(); ++i) {
    const TransitionRow& begin = transitions[i];
    if (!is_fault(begin.to)) continue;
    // It ends with the next state the run takes, but `queued`: an interrupted run that is resumed
    // waits in the queue before it records again.
    std::size_t end = i + 1;
    while (end < transitions.size() && transitions[end].to == RunState::Queued) ++end;
    std::size_t next_fault = i + 1;
    while (next_fault < transitions.size() && !is_fault(transitions[next_fault].to)) ++next_fault;
    const std::int64_t until_ms =
        next_fault < transitions.size() ? transitions[next_fault].t_ms : std::numeric_limits<std::int64_t>::max();
    const auto program_time_s = program_time_of(begin.to, events, begin.t_ms, until_ms);
    out.push_back({{"state", to_string(begin.to)},
                   {"reason", begin.reason},
                   {"start", iso8601_utc(begin.t_ms)},
                   {"end", end < transitions.size() ? json(iso8601_utc(transitions[end].t_ms)) : json(nullptr)},
                   {"program_time_s", program_time_s ? json(*program_time_s) : json(nullptr)}});
  }
  return out;
}

}  // namespace imucal::daemon
