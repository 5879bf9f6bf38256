// The sequencer: runs the queued campaigns one after another on the bench, each through the run
// engine (daemon/run/engine.hpp), whose documents go to the run's subscribers, in this order: the
// service database, alarms, the live feed, the run file's record, then any added by subscribe()
// (the service adds the certificates': the transitions' audit trail and a run's certificate at its
// end), and last the online estimators, which emit documents of their own (docs/ARCHITECTURE.md
// "The run engine"). It owns the operator's commands and the active run's
// state (RunControl), the campaigns' queue, and the service's WriteQueue.
#pragma once

#include <condition_variable>
#include <cstdint>
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
#include "daemon/db/write_queue.hpp"
#include "daemon/run/documents.hpp"
#include "daemon/run/engine.hpp"
#include "daemon/run/run_control.hpp"
#include "daemon/subscribers/alarms.hpp"
#include "daemon/subscribers/estimators.hpp"
#include "daemon/subscribers/live.hpp"
#include "daemon/subscribers/run_file.hpp"
#include "daemon/subscribers/service_db.hpp"

namespace imucal::daemon {

class Sequencer final : private RunControl {
 public:
  // Events for the live view ({"type": "event", ...} and {"type": "alarm", ...}, without seq and
  // t); called on the thread that made the event, never under the sequencer's lock.
  using EventListener = LiveFeed::Listener;

  Sequencer(const DaemonConfig& config, DaemonDb& db);
  ~Sequencer() override;
  Sequencer(const Sequencer&) = delete;
  Sequencer& operator=(const Sequencer&) = delete;

  void set_event_listener(EventListener listener) { live_.set_listener(std::move(listener)); }
  // One more subscriber of every run's documents, after the sequencer's own (documents.hpp);
  // refused (std::logic_error) while a run is active.
  void subscribe(RunSubscriber& subscriber);

  // Seams for tests that need a slow or a full disk under a run; none in service.
  using RecorderHooks = RunFiles::Hooks;
  void set_recorder_hooks(RecorderHooks hooks) { run_files_.set_hooks(std::move(hooks)); }
  // Starts the queue runner (after the database's crash recovery).
  void start();
  // Parks the active run (table stopped, interlock open, chamber safe, recording flushed; the run
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
  nlohmann::json telemetry() const { return live_.telemetry(); }
  std::optional<std::int64_t> active_id() const;
  // Progress of the active run's estimators (latest), for GET /api/campaigns/{id}.
  nlohmann::json active_estimators() const { return live_.estimators(); }

  // A write to the daemon database through the service's WriteQueue (write_queue.hpp): stored now
  // when the database takes it, else kept in memory in order. Returns whether it was stored now.
  bool write_db(const std::string& what, std::function<void()> write) { return writes_.write(what, std::move(write)); }
  // How many writes wait in memory for the database (0 unless it could not be written).
  std::size_t deferred_writes() const { return writes_.size(); }

 private:
  // RunControl, for the engine.
  std::optional<Request> pending() override;
  RunState state() const override;
  bool transition(RunState to, const std::string& reason, std::optional<RunState> expected) override;
  void wait(std::chrono::milliseconds timeout) override;
  void ask(std::size_t segment, const std::string& text) override;
  std::optional<std::string> take_answer() override;
  void withdraw_prompt() override;
  nlohmann::json prompt() const override;

  void runner();
  // The next queued campaign, now running (stored); nothing when none may start.
  std::optional<RunEngine::Request> claim_next(std::unique_lock<std::mutex>& lock);
  // Emits a state change, in order: called with `lock` (the sequencer's) held, where the change
  // takes its place in line (a ticket); the lock is released before it waits for its turn, so a
  // subscriber may call the sequencer's getters (the certificate reads the prompt) while another
  // thread's change waits. A subscriber must not change a run's state itself: it would wait for
  // its own turn.
  void emit_transition(std::unique_lock<std::mutex>& lock, const Transition& transition);
  void fail_active(std::int64_t id, const std::string& why);
  // Campaign `id`'s prompt while unanswered, else null; with mutex_ held.
  nlohmann::json prompt_json(std::int64_t id) const;

  DaemonDb& db_;
  WriteQueue writes_;
  // The subscribers, in the order they are given the documents.
  Documents documents_;
  ServiceDbSubscriber service_db_;
  AlarmsSubscriber alarms_;
  RunFiles run_files_;
  LiveFeed live_;
  EstimatorsSubscriber estimators_;
  RunEngine engine_;

  mutable std::mutex mutex_;  // guards the members below and every state change
  std::condition_variable cv_;
  // The transitions' order: each takes the next ticket under mutex_ and is delivered when
  // served_ reaches it (under order_mutex_, never held with mutex_ nor while delivering).
  std::uint64_t next_ticket_ = 0;
  std::mutex order_mutex_;
  std::condition_variable order_cv_;
  std::uint64_t served_ = 0;
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
  std::thread thread_;
};

}  // namespace imucal::daemon
