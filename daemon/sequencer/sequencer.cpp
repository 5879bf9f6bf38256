#include "daemon/sequencer/sequencer.hpp"

#include <chrono>
#include <stdexcept>
#include <vector>

#include <spdlog/spdlog.h>

namespace imucal::daemon {

using nlohmann::json;

Sequencer::Sequencer(const DaemonConfig& config, DaemonDb& db)
    : db_(db),
      service_db_(db, writes_),
      alarms_(db, writes_, [this](const json& message) { live_.tell(message); }),
      run_files_(config, db),
      live_(config),
      estimators_(db, documents_),
      engine_(config, *this, documents_, run_files_, storage_disk_switch()),
      queue_enabled_(config.queue_autostart) {
  documents_.subscribe(service_db_);
  documents_.subscribe(alarms_);
  documents_.subscribe(live_);
  documents_.subscribe(run_files_);
  documents_.subscribe_emitter(estimators_);  // after any subscriber added later
}

Sequencer::~Sequencer() { shutdown(); }

void Sequencer::start() {
  if (thread_.joinable()) return;
  thread_ = std::thread([this] { runner(); });
}

void Sequencer::shutdown() {
  {
    std::lock_guard lock(mutex_);
    shutdown_ = true;
  }
  cv_.notify_all();
  if (thread_.joinable()) thread_.join();
  // What a full disk kept back is stored now if it can be; what cannot is named in the log (the
  // next start's crash recovery makes an unstored running state interrupted).
  if (!writes_.retry()) writes_.give_up();
}

void Sequencer::subscribe(RunSubscriber& subscriber) {
  for (;;) {
    std::unique_lock lock(mutex_);
    if (active_id_) throw std::logic_error("a subscriber is added only while no run is active");
    const std::uint64_t issued = next_ticket_;
    std::unique_lock order(order_mutex_);
    if (served_ == issued) {  // no transition is being delivered nor waits
      documents_.subscribe(subscriber);
      return;
    }
    lock.unlock();  // never wait for the order with mutex_ held (emit_transition)
    order_cv_.wait(order, [&] { return served_ >= issued; });
  }
}

std::optional<std::int64_t> Sequencer::active_id() const {
  std::lock_guard lock(mutex_);
  return active_id_;
}

void Sequencer::emit_transition(std::unique_lock<std::mutex>& lock, const Transition& transition) {
  const std::uint64_t ticket = next_ticket_++;
  lock.unlock();
  cv_.notify_all();
  std::unique_lock order(order_mutex_);
  order_cv_.wait(order, [&] { return served_ == ticket; });
  order.unlock();
  // The next in line is served even when a subscriber throws.
  struct Served {
    Sequencer& s;
    ~Served() {
      {
        std::lock_guard order(s.order_mutex_);
        ++s.served_;
      }
      s.order_cv_.notify_all();
    }
  } served{*this};
  documents_.emit(&RunSubscriber::transition, transition);
}

// ------------------------------------------------------------------------------------------------
// Commands

Sequencer::CommandOutcome Sequencer::command(std::int64_t id, Command command, const std::string& who,
                                             const std::string& reason) {
  const std::string why = std::string(to_string(command)) + " by " + who + (reason.empty() ? "" : ": " + reason);
  std::unique_lock lock(mutex_);
  if (shutdown_) return {503, "the daemon is shutting down", std::nullopt};
  const bool active = active_id_ == id;
  // The active run's state is the sequencer's, and its change reaches the database in order with
  // the ones a full disk kept back (an operator can stop or abort a run suspended on a full disk);
  // another campaign's state is the database's, which must first hold every change kept back.
  if (!active && !writes_.retry())
    return {503, "the daemon database cannot be written now (is the disk full?); try again later", std::nullopt};
  auto row = db_.campaign(id);
  if (!row) return {404, "no campaign " + std::to_string(id), std::nullopt};
  const RunState state = active ? active_state_ : row->state;
  const auto target = command_target(state, command);
  if (!target || (is_active(state) && !active)) {
    std::string message = "cannot " + std::string(to_string(command)) + " campaign " + std::to_string(id) +
                          ": it is " + std::string(to_string(state));
    if (command == Command::Start && state != RunState::Created)
      message = "campaign " + std::to_string(id) + " was already started (state " + std::string(to_string(state)) +
                "); post it again to repeat it";
    if (command == Command::Resume && state == RunState::Suspended)
      message += "; a suspended run resumes by itself when the condition has cleared";
    return {409, message, state};
  }
  if (active) {
    active_state_ = *target;
  } else if (!db_.set_state(id, *target, why)) {
    return {409, "campaign " + std::to_string(id) + " changed meanwhile", state};
  }
  if (*target == RunState::Queued) {
    if (state == RunState::Interrupted) {
      db_.queue_push_front(id);
    } else {
      db_.queue_push_back(id);
    }
    queue_enabled_ = true;
  }
  if (*target == RunState::Aborted && !active) db_.queue_remove(id);  // an active run is in no queue
  spdlog::info("campaign {}: {}", id, why);
  emit_transition(lock, Transition{id, state, *target, why, !active});
  return {200, "", *target};
}

Sequencer::CommandOutcome Sequencer::answer_prompt(std::int64_t id, const std::string& who) {
  {
    std::lock_guard lock(mutex_);
    if (!prompt_ || prompt_->campaign != id || prompt_->answered_by)
      return {409, "campaign " + std::to_string(id) + " is not waiting for an answer", std::nullopt};
    prompt_->answered_by = who;
  }
  cv_.notify_all();
  spdlog::info("campaign {}: prompt answered by {}", id, who);
  return {};
}

json Sequencer::prompt_of(std::int64_t id) const {
  std::lock_guard lock(mutex_);
  return prompt_json(id);
}

json Sequencer::prompt_json(std::int64_t id) const {
  if (!prompt_ || prompt_->campaign != id || prompt_->answered_by) return nullptr;
  return {{"text", prompt_->text}, {"since", prompt_->since}, {"segment", prompt_->segment}};
}

// ------------------------------------------------------------------------------------------------
// RunControl: the active run's side of the commands

std::optional<RunControl::Request> Sequencer::pending() {
  std::lock_guard lock(mutex_);
  if (shutdown_) return Request::Shutdown;
  switch (active_state_) {
    case RunState::Pausing: return Request::Pause;
    case RunState::Stopping: return Request::Stop;
    case RunState::Aborting: return Request::Abort;
    default: return std::nullopt;
  }
}

RunState Sequencer::state() const {
  std::lock_guard lock(mutex_);
  return active_state_;
}

bool Sequencer::transition(RunState to, const std::string& reason, std::optional<RunState> expected) {
  std::unique_lock lock(mutex_);
  if (!active_id_) return false;
  if (expected && active_state_ != *expected) return false;
  const RunState from = active_state_;
  active_state_ = to;
  spdlog::info("campaign {}: {} -> {} ({})", *active_id_, to_string(from), to_string(to), reason);
  emit_transition(lock, Transition{*active_id_, from, to, reason, false});
  return true;
}

void Sequencer::wait(std::chrono::milliseconds timeout) {
  std::unique_lock lock(mutex_);
  cv_.wait_for(lock, timeout);
}

void Sequencer::ask(std::size_t segment, const std::string& text) {
  std::lock_guard lock(mutex_);
  prompt_ = Prompt{active_id_.value_or(0), segment, text, iso8601_utc(now_unix_ms()), std::nullopt};
}

std::optional<std::string> Sequencer::take_answer() {
  std::lock_guard lock(mutex_);
  if (!prompt_ || !prompt_->answered_by) return std::nullopt;
  std::optional<std::string> who = prompt_->answered_by;
  prompt_.reset();
  return who;
}

void Sequencer::withdraw_prompt() {
  std::lock_guard lock(mutex_);
  prompt_.reset();
}

json Sequencer::prompt() const {
  std::lock_guard lock(mutex_);
  return active_id_ ? prompt_json(*active_id_) : json(nullptr);
}

// ------------------------------------------------------------------------------------------------
// The queue runner

std::optional<RunEngine::Request> Sequencer::claim_next(std::unique_lock<std::mutex>& lock) {
  lock.unlock();
  const bool stored = writes_.retry();
  lock.lock();
  std::vector<std::int64_t> queue;
  std::optional<CampaignRow> row;
  std::string reason;
  // A database that cannot be read or written (disk full) starts nothing: the queue waits.
  try {
    cv_.wait_for(lock, std::chrono::milliseconds(500), [&] {
      if (shutdown_) return true;
      if (!queue_enabled_ || !stored) return false;
      queue = db_.queue();
      return !queue.empty();
    });
    if (shutdown_ || !queue_enabled_ || queue.empty()) return std::nullopt;
    const std::int64_t id = queue.front();
    row = db_.campaign(id);
    if (!row || row->state != RunState::Queued) {
      db_.queue_remove(id);
      return std::nullopt;
    }
    reason = row->run_db.empty() ? "devices free: starting" : "resuming from the last checkpoint";
    if (!db_.set_state(id, RunState::Running, reason, RunState::Queued)) return std::nullopt;
    db_.queue_remove(id);
  } catch (const std::exception& e) {
    spdlog::error("the queue waits: {}", e.what());
    cv_.wait_for(lock, std::chrono::seconds(1), [&] { return shutdown_; });
    return std::nullopt;
  }
  active_id_ = row->id;
  active_state_ = RunState::Running;
  spdlog::info("campaign {}: queued -> running ({})", row->id, reason);
  emit_transition(lock, Transition{row->id, RunState::Queued, RunState::Running, reason, true});
  lock.lock();
  return RunEngine::Request{row->id, row->spec_json, row->lost_frames, row->bad_frames};
}

// The last line of defence: the engine handles its own failures, and this must not throw itself
// (the database it writes to may be on the disk that failed: each write is kept by the WriteQueue).
void Sequencer::fail_active(std::int64_t id, const std::string& why) {
  spdlog::critical("campaign {}: unexpected error: {}", id, why);
  try {
    documents_.emit(&RunSubscriber::error, RunError{id, why});
    documents_.emit(&RunSubscriber::event, RunEvent{id, "error", std::nullopt, std::nullopt, "internal error: " + why});
    transition(RunState::Failed, "internal error: " + why, std::nullopt);
  } catch (const std::exception& again) {
    spdlog::critical("campaign {}: its failure not stored: {}", id, again.what());
  }
}

void Sequencer::runner() {
  std::unique_lock lock(mutex_);
  while (!shutdown_) {
    const std::optional<RunEngine::Request> next = claim_next(lock);
    if (!next) continue;
    lock.unlock();
    try {
      engine_.run(*next);
    } catch (const std::exception& e) {
      fail_active(next->campaign, e.what());
    }
    lock.lock();
    active_id_.reset();
    live_.idle();
  }
}

}  // namespace imucal::daemon
