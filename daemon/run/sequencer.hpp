// The sequencer: runs the queued campaigns one after another on the bench, segment by segment,
// with the run state machine of run_state.hpp, the suspenders (chamber out of band, IMU frames
// missing or corrupt, a device disconnected, a table fault: safe hold, automatic resume after the
// condition clears plus a settle time, the interrupted segment redone), operator commands, the
// recorder and the online estimators, and the telemetry the live view shows.
//
// Checkpoints are the program's segment boundaries. Frames already recorded are never recorded
// again: a redone segment records only frames after the last one handed to the recorder, so the
// run file holds every program instant exactly once whatever happened (pause, suspension, crash).
// Every path out of a run leaves the table at rate zero with its interlock open and the chamber
// at its safe set point.
#pragma once

#include <atomic>
#include <condition_variable>
#include <cstdint>
#include <deque>
#include <functional>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <thread>

#include <nlohmann/json.hpp>

#include "daemon/config/config.hpp"
#include "daemon/db/daemon_db.hpp"
#include "daemon/db/run_state.hpp"
#include "daemon/run/suspenders.hpp"
#include "storage/recorder.hpp"

namespace imucal::daemon {

struct RunContext;
class PowerSwitch;

class Sequencer {
 public:
  // Events for the live view ({"type": "event", ...} and {"type": "alarm", ...}, without seq and
  // t); called on the thread that made the event, never under the sequencer's lock.
  using EventListener = std::function<void(const nlohmann::json&)>;

  Sequencer(const DaemonConfig& config, DaemonDb& db);
  ~Sequencer();
  Sequencer(const Sequencer&) = delete;
  Sequencer& operator=(const Sequencer&) = delete;

  void set_event_listener(EventListener listener);

  // Seams for tests that need a slow or a full disk under a run; none in service.
  struct RecorderHooks {
    // Called with the run file before each recorder of a run takes it: attempt 0 at the start,
    // 1, 2, ... each time the file is reopened after a write failure.
    std::function<void(storage::RunDb&, int attempt)> on_open;
    // Called on the writer thread after every commit.
    std::function<void(const storage::RecorderStats&)> after_commit;
    // Overrides the bench: false drops frames on a full queue, as with real devices.
    std::optional<bool> wait_when_full;
  };
  void set_recorder_hooks(RecorderHooks hooks);
  // Starts the queue runner (after the database's crash recovery).
  void start();
  // Parks the active run (table stopped, interlock open, chamber safe, recorder flushed; the run
  // becomes interrupted) and ends the runner. Idempotent.
  void shutdown();

  struct CommandOutcome {
    int http_status = 200;
    std::string error;
    std::optional<RunState> state;
  };
  // An operator command (thread-safe). `who` and `reason` go into the transition's reason.
  CommandOutcome command(std::int64_t id, Command command, const std::string& who, const std::string& reason);

  // The operator's answer to the active run's prompt (a power-cycle segment waits for it): 200, or
  // 409 when campaign `id` is not waiting for one.
  CommandOutcome answer_prompt(std::int64_t id, const std::string& who);
  // What campaign `id` asks now ({"text", "since", "segment"}), or null: the telemetry's run.prompt
  // and the campaign's prompt.
  nlohmann::json prompt_of(std::int64_t id) const;

  // The latest telemetry (the live message without type, seq and t).
  nlohmann::json telemetry() const;
  std::optional<std::int64_t> active_id() const;
  // Progress of the active run's estimators (latest), for GET /api/campaigns/{id}.
  nlohmann::json active_estimators() const;

  // A write to the daemon database that a full disk (or an I/O error) must not turn into a failed
  // run, a lost audit entry or a dead daemon: done now when the database takes it, else kept in memory in order and
  // tried again (retry_db_writes, from publish and the queue runner) -- the run goes on with its
  // state in memory meanwhile. Later writes queue behind a deferred one, so the database sees
  // them in their order. Returns whether it was stored now. Other errors propagate.
  bool write_db(const std::string& what, std::function<void()> write);
  // How many writes wait in memory for the database (0 unless it could not be written).
  std::size_t deferred_writes() const;

 private:
  friend struct RunContext;
  enum class Outcome { Completed, Redo, Pause, Stop, Abort, Shutdown, Fail };

  void runner();
  void run_campaign(std::int64_t id);
  bool open_run(RunContext& run);
  Outcome run_program(RunContext& run);
  void store_progress(std::int64_t id, const std::string& name, double t_s, const nlohmann::json& progress);
  bool transition(std::int64_t id, RunState to, const std::string& reason, std::optional<RunState> expected);
  void note_event(RunContext& run, const std::string& kind, const std::string& reason);
  // Stores a run event; an event of a serious kind also raises its alarm (alarms.hpp), broadcast.
  void record_event(std::int64_t id, const std::string& kind, std::optional<std::int64_t> segment,
                    std::optional<double> program_time_s, const std::string& reason);
  // Clears and raises the alarms a state change implies (alarms.hpp), broadcast.
  void transition_alarms(std::int64_t id, RunState from, RunState to, const std::string& reason);
  // The run's state: stored now, or deferred as write_db does (then taken as done).
  bool store_state(std::int64_t id, RunState to, const std::string& reason, std::optional<RunState> expected);
  // Tries the deferred writes again, oldest first, up to the first that still fails. True when
  // none is left.
  bool retry_db_writes();
  std::optional<Outcome> pending_command();
  RunState active_state() const;

  void check_unit(RunContext& run);
  // Commits what the recorder holds; false when it cannot (marks the run file failed when the
  // recorder has stopped, not when it holds its frames for want of space).
  bool commit_recording(RunContext& run);
  void open_recorder(RunContext& run);
  std::optional<std::string> recorder_problem(RunContext& run);
  Outcome prepare_devices(RunContext& run);
  Outcome run_segment(RunContext& run);
  Outcome hold(RunContext& run, const std::string& reason);
  Outcome paused(RunContext& run);
  // Before a power-cycle segment: the table safe, the operator asked to switch the IMU off and on;
  // waits for the answer (or a command).
  Outcome await_power_cycle(RunContext& run);
  std::optional<Outcome> switch_power(RunContext& run, PowerSwitch& power, std::string& failure);
  Outcome wait_until_ready(RunContext& run, bool suspended);
  DeviceReadings readings(RunContext& run, double setpoint_C, double tolerance_C);
  void safe_hold(RunContext& run);
  void safe_exit(RunContext& run);
  void finish_run(RunContext& run, Outcome outcome, const std::string& reason);
  void store_estimator_results(RunContext& run);
  void publish(RunContext& run, bool force);
  void emit(const nlohmann::json& event);

  const DaemonConfig& config_;
  DaemonDb& db_;
  EventListener listener_;

  mutable std::mutex mutex_;  // guards the members below and every state change
  std::condition_variable cv_;
  std::optional<std::int64_t> active_id_;
  RunState active_state_ = RunState::Created;
  bool shutdown_ = false;
  bool queue_enabled_ = true;
  // What the active run asks the operator (telemetry "run.prompt"), until it is answered.
  struct Prompt {
    std::int64_t campaign = 0;
    std::size_t segment = 0;
    std::string text, since;
    std::optional<std::string> answered_by;
  };
  std::optional<Prompt> prompt_;
  RecorderHooks recorder_hooks_;
  mutable std::mutex db_writes_mutex_;  // guards deferred_writes_ and orders the writes through it
  std::deque<std::pair<std::string, std::function<void()>>> deferred_writes_;
  std::thread thread_;

  mutable std::mutex telemetry_mutex_;
  nlohmann::json telemetry_;
  nlohmann::json estimators_;  // latest progress per estimator of the active run
};

}  // namespace imucal::daemon
