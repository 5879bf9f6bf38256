#include "daemon/db/run_state.hpp"

#include <array>
#include <string>
#include <utility>

namespace imucal::daemon {

namespace {

constexpr std::array<std::pair<RunState, std::string_view>, 12> kStateNames = {{
    {RunState::Created, "created"},
    {RunState::Queued, "queued"},
    {RunState::Running, "running"},
    {RunState::Pausing, "pausing"},
    {RunState::Paused, "paused"},
    {RunState::Suspended, "suspended"},
    {RunState::Stopping, "stopping"},
    {RunState::Aborting, "aborting"},
    {RunState::Done, "done"},
    {RunState::Failed, "failed"},
    {RunState::Aborted, "aborted"},
    {RunState::Interrupted, "interrupted"},
}};

constexpr std::array<std::pair<Command, std::string_view>, 5> kCommandNames = {{
    {Command::Start, "start"},
    {Command::Pause, "pause"},
    {Command::Resume, "resume"},
    {Command::Stop, "stop"},
    {Command::Abort, "abort"},
}};

}  // namespace

std::string_view to_string(RunState state) {
  for (const auto& [s, name] : kStateNames)
    if (s == state) return name;
  return "unknown";
}

std::optional<RunState> parse_run_state(std::string_view text) {
  for (const auto& [s, name] : kStateNames)
    if (name == text) return s;
  return std::nullopt;
}

std::string_view to_string(Command command) {
  for (const auto& [c, name] : kCommandNames)
    if (c == command) return name;
  return "unknown";
}

std::optional<Command> parse_command(std::string_view text) {
  for (const auto& [c, name] : kCommandNames)
    if (name == text) return c;
  return std::nullopt;
}

bool is_final(RunState state) {
  return state == RunState::Done || state == RunState::Failed || state == RunState::Aborted;
}

bool is_active(RunState state) {
  switch (state) {
    case RunState::Running:
    case RunState::Pausing:
    case RunState::Paused:
    case RunState::Suspended:
    case RunState::Stopping:
    case RunState::Aborting:
      return true;
    default:
      return false;
  }
}

bool transition_allowed(RunState from, RunState to) {
  using S = RunState;
  // The end of an active run: done (completed, or stopped with results), failed, or interrupted
  // (the daemon shut down); aborted only through aborting.
  const auto ends = [&](bool can_finish) {
    return (can_finish && to == S::Done) || to == S::Failed || to == S::Interrupted;
  };
  switch (from) {
    case S::Created: return to == S::Queued || to == S::Aborted;
    case S::Queued: return to == S::Running || to == S::Aborted;
    case S::Running:
      return to == S::Pausing || to == S::Suspended || to == S::Stopping || to == S::Aborting || ends(true);
    case S::Pausing:
      return to == S::Paused || to == S::Stopping || to == S::Aborting || ends(true);
    case S::Paused: return to == S::Running || to == S::Stopping || to == S::Aborting || ends(false);
    case S::Suspended: return to == S::Running || to == S::Stopping || to == S::Aborting || ends(false);
    case S::Stopping: return to == S::Aborting || ends(true);
    case S::Aborting: return to == S::Aborted || to == S::Failed || to == S::Interrupted;
    case S::Interrupted: return to == S::Queued || to == S::Aborted;
    case S::Done:
    case S::Failed:
    case S::Aborted: return false;  // final: nothing more happens
  }
  return false;
}

InvalidTransition::InvalidTransition(std::int64_t id, RunState f, RunState t)
    : std::logic_error("campaign " + std::to_string(id) + ": no transition from " + std::string(to_string(f)) + " to " +
                       std::string(to_string(t)) + " (the run's transition table, docs/daemon.md)"),
      campaign(id),
      from(f),
      to(t) {}

std::optional<RunState> command_target(RunState from, Command command) {
  switch (command) {
    case Command::Start:
      if (from == RunState::Created) return RunState::Queued;
      break;
    case Command::Pause:
      if (from == RunState::Running) return RunState::Pausing;
      break;
    case Command::Resume:
      if (from == RunState::Paused) return RunState::Running;
      // An interrupted run goes back to the head of the queue: the devices may be busy, and the
      // table must be homed again before anything moves.
      if (from == RunState::Interrupted) return RunState::Queued;
      break;
    case Command::Stop:
      if (from == RunState::Running || from == RunState::Pausing || from == RunState::Paused ||
          from == RunState::Suspended)
        return RunState::Stopping;
      break;
    case Command::Abort:
      if (from == RunState::Created || from == RunState::Queued || from == RunState::Interrupted)
        return RunState::Aborted;
      if (is_active(from) && from != RunState::Aborting) return RunState::Aborting;
      break;
  }
  return std::nullopt;
}

}  // namespace imucal::daemon
