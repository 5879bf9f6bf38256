// The run state machine of a campaign: one enum shared by the API, the UI (as strings) and the
// daemon database, the operator commands, and which command is allowed in which state; and the
// table of every transition a run may make, the operator's and the sequencer's alike
// (running <-> suspended, -> done/failed/...), which the daemon database enforces on every change.
#pragma once

#include <cstdint>
#include <optional>
#include <stdexcept>
#include <string>
#include <string_view>

namespace imucal::daemon {

enum class RunState {
  Created,      // posted and validated, not started (not a run yet)
  Queued,       // started, waiting for the devices
  Running,
  Pausing,      // pause requested; the table is being brought to a safe hold
  Paused,
  Suspended,    // safe hold because a suspender tripped; resumes by itself
  Stopping,     // ending early with results from the data so far
  Aborting,     // ending at once; then the estimators finish on the data so far (partial)
  Done,
  Failed,
  Aborted,
  Interrupted,  // found non-final at start-up (crash) or parked by a shutdown
};

enum class Command { Start, Pause, Resume, Stop, Abort };

std::string_view to_string(RunState state);
std::optional<RunState> parse_run_state(std::string_view text);
std::string_view to_string(Command command);
std::optional<Command> parse_command(std::string_view text);

// Done, failed, aborted: nothing more happens to the campaign.
bool is_final(RunState state);
// The sequencer owns the devices in these states (the run is "active").
bool is_active(RunState state);

// Whether a run may go from `from` to `to` (the table in run_state.cpp; docs/daemon.md draws it).
bool transition_allowed(RunState from, RunState to);

// A state change the table does not allow: a defect of the code that asked for it, never silently
// written.
class InvalidTransition : public std::logic_error {
 public:
  InvalidTransition(std::int64_t campaign, RunState from, RunState to);
  std::int64_t campaign;
  RunState from, to;
};

// The state an operator command leads to from `from`, or nothing when the command does not apply.
// Only the immediate state: pause gives Pausing (the sequencer makes Paused), stop Stopping, ...
std::optional<RunState> command_target(RunState from, Command command);

}  // namespace imucal::daemon
