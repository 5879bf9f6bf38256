// What the run loop asks of whoever runs it (the sequencer): the operator's commands, the active
// run's state and its changes, and the operator's answer to a prompt. The loop holds no lock of
// its own; these calls are thread-safe.
#pragma once

#include <chrono>
#include <cstddef>
#include <optional>
#include <string>

#include <nlohmann/json.hpp>

#include "daemon/db/run_state.hpp"

namespace imucal::daemon {

class RunControl {
 public:
  virtual ~RunControl() = default;
  // What ends the run's current step: an operator's pause, stop or abort, or the daemon's shutdown.
  enum class Request { Pause, Stop, Abort, Shutdown };
  virtual std::optional<Request> pending() = 0;
  virtual RunState state() const = 0;
  // The active run's state to `to` (false when it is not `expected`: a command came first),
  // emitted as a Transition document.
  virtual bool transition(RunState to, const std::string& reason, std::optional<RunState> expected) = 0;
  // Waits up to `timeout` for a command, an answer or the shutdown.
  virtual void wait(std::chrono::milliseconds timeout) = 0;
  // The operator is asked `text` before segment `segment` (telemetry run.prompt) until answered.
  virtual void ask(std::size_t segment, const std::string& text) = 0;
  // Who answered the prompt, taking it; nothing while it waits.
  virtual std::optional<std::string> take_answer() = 0;
  virtual void withdraw_prompt() = 0;  // asked again when the run comes back to it
  // What the active run asks now ({"text", "since", "segment"}), or null.
  virtual nlohmann::json prompt() const = 0;
};

}  // namespace imucal::daemon
