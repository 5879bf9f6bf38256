#include "daemon/run/sequencer.hpp"

#include <chrono>
#include <cmath>
#include <filesystem>
#include <limits>

#include <spdlog/spdlog.h>

#include "core/number_text.hpp"
#include "core/units.hpp"
#include "daemon/campaign/campaign.hpp"
#include "daemon/devices/bench_factory.hpp"
#include "daemon/run/alarms.hpp"
#include "daemon/run/estimator_worker.hpp"
#include "daemon/run/faulted_intervals.hpp"
#include "storage/bundle.hpp"
#include "storage/recorder.hpp"
#include "storage/run_db.hpp"
#include "storage/sqlite.hpp"

namespace imucal::daemon {

using nlohmann::json;
using Clock = std::chrono::steady_clock;
namespace fs = std::filesystem;

namespace {

double seconds(Clock::duration d) { return std::chrono::duration<double>(d).count(); }

json vec3(const Eigen::Vector3d& v) { return json::array({v.x(), v.y(), v.z()}); }

// A simulated bench's disk_full fault fills storage's full-disk switch (the devices do not reach
// storage; the sequencer, which records, does).
DiskFaultSwitch storage_disk_switch() {
  return {[](bool full) { storage::disk_fault::set_full(full); }, [] { return storage::disk_fault::refused_writes(); }};
}

}  // namespace

// Everything about the run in progress; lives on the sequencer thread only.
struct RunContext {
  std::int64_t id = 0;
  CampaignRow row;
  CampaignSpec spec;
  motion::Program program;
  std::vector<SegmentInfo> segments;
  std::unique_ptr<Bench> bench;
  // The recorder's commit listener reaches the worker through this pointer. Declared in this
  // order so that the recorder (its thread) goes first and the worker outlives it.
  std::atomic<EstimatorWorker*> worker{nullptr};
  bool estimators_finishing = false;  // the program has ended; the estimators work through its tail
  std::unique_ptr<EstimatorWorker> estimators;
  // Alarms raised by the recorder (on the pushing or the writer thread), taken by the sequencer.
  // Declared before the recorder, whose handler uses them until it is gone.
  std::mutex alarm_mutex;
  std::vector<storage::RecorderAlarm> alarms;
  std::unique_ptr<storage::Recorder> recorder;
  int recorder_opens = 0;  // recorders started on the run file in this run
  std::string run_db_path;
  // The producer waits for room in the recorder's queue (simulation paced by the recorder); when
  // false a full queue drops frames, as it must with devices that do not wait.
  bool recorder_waits = true;
  // The recorder failed (disk full, damaged file): the run holds until the file reopens.
  bool recorder_failed = false;

  std::size_t segment = 0;
  std::int64_t dt_ns = 0;
  std::optional<std::int64_t> last_t_ns;       // last frame handed to the recorder
  std::optional<std::int64_t> last_temp_t_ns;  // last temperature handed to the recorder
  std::int64_t frames = 0, lost = 0, bad = 0;
  std::int64_t prev_delivered_t_ns = 0;        // last frame the IMU delivered in this pass
  std::int64_t delivered = 0;
  double last_frame_world_s = 0.0;
  std::unique_ptr<Suspenders> suspenders;  // from the campaign's settings, at the run's start
  double program_time_s = 0.0;
  std::optional<double> commanded_setpoint_C;
  std::optional<std::string> reported_serial;  // what the IMU said it is (check_unit)
  // The power-cycle segment whose prompt the operator answered: a redo of it does not ask again.
  std::optional<std::size_t> power_cycled_segment;

  Clock::time_point last_publish{}, last_db_update{}, window_wall{};
  double window_world_s = 0.0;
  std::int64_t window_delivered = 0;
  double speed_factor = 0.0, frame_rate_hz = 0.0;

  std::int64_t segment_end_ns(std::size_t k) const {
    return std::llround(segments[k].t1_s * units::kNsPerS);
  }
  double checkpoint_s() const { return segment < segments.size() ? segments[segment].t0_s : program.duration_s(); }
  // Where to (re)start: the segment holding the frame after the last committed one.
  void place_at_committed() {
    segment = segments.size();
    const std::int64_t next_t_ns = last_t_ns ? *last_t_ns + dt_ns : 0;
    for (std::size_t k = 0; k < segments.size(); ++k) {
      if (next_t_ns <= segment_end_ns(k)) {
        segment = k;
        break;
      }
    }
    program_time_s = last_t_ns ? static_cast<double>(*last_t_ns) / units::kNsPerS : 0.0;
  }
};

Sequencer::Sequencer(const DaemonConfig& config, DaemonDb& db)
    : config_(config), db_(db), queue_enabled_(config.queue_autostart) {
  telemetry_ = {{"run", nullptr},
                {"table", {{"angle_deg", {0, 0, 0}}, {"rate_dps", {0, 0, 0}}, {"homed", false},
                           {"interlock_closed", false}, {"connected", true}, {"fault", nullptr}}},
                {"chamber", {{"temperature_C", config.chamber.safe_setpoint_C},
                             {"setpoint_C", config.chamber.safe_setpoint_C},
                             {"tolerance_C", config.chamber.tolerance_C}, {"in_band", true}, {"connected", true}}},
                {"imu", {{"frame_rate_hz", 0.0}, {"frames", 0}, {"lost_frames", 0}, {"bad_frames", 0},
                         {"connected", true}}},
                {"recorder", {{"queue_frames", 0}, {"queue_high_water_frames", 0}, {"committed_frames", 0}}},
                {"estimators", json::object()}};
}

Sequencer::~Sequencer() { shutdown(); }

void Sequencer::set_event_listener(EventListener listener) { listener_ = std::move(listener); }

void Sequencer::set_recorder_hooks(RecorderHooks hooks) {
  std::lock_guard lock(mutex_);
  recorder_hooks_ = std::move(hooks);
}

// What the run file records about the run: the bench's description, with the IMU's serial that
// of the campaign's unit when it names one (checked against what the IMU reported, check_unit),
// else the one the IMU reported, else the bench's configured or simulated serial.
static RecordingMeta recording_meta(const RunContext& run) {
  RecordingMeta meta = run.bench->imu().recording_meta();
  if (run.reported_serial) meta.imu_serial = *run.reported_serial;
  if (!run.spec.imu.serial.empty()) meta.imu_serial = run.spec.imu.serial;
  return meta;
}

// The unit on the link must be the campaign's (issue 17): an IMU whose link carries its serial
// number is asked for it before anything moves or is recorded; a different serial stops the start
// with both values. One that says nothing within the wait is noted, and the run goes on.
void Sequencer::check_unit(RunContext& run) {
  Imu& imu = run.bench->imu();
  if (!imu.reports_serial()) return;
  constexpr double kWait_s = 3.0;
  run.reported_serial = imu.reported_serial(kWait_s);
  if (!run.reported_serial) {
    note_event(run, "alarm", "the IMU did not report its serial number within 3 s: the unit on the link is not checked");
    return;
  }
  if (!run.spec.imu.serial.empty() && *run.reported_serial != run.spec.imu.serial)
    throw std::runtime_error("the IMU on the link reports serial number '" + *run.reported_serial +
                             "', but the campaign names the unit '" + run.spec.imu.serial +
                             "': not started, nothing recorded (mount the named unit, or correct campaign.imu.serial)");
  note_event(run, "info", "the IMU reports serial number '" + *run.reported_serial + "'" +
                              (run.spec.imu.serial.empty() ? std::string() : ", the campaign's unit"));
}

// Opens the run file (creating it on the first start, recovering it after a crash or a failed
// write), takes up from what it holds, and starts a recorder on it.
void Sequencer::open_recorder(RunContext& run) {
  RecorderHooks hooks;
  {
    std::lock_guard lock(mutex_);
    hooks = recorder_hooks_;
  }
  const bool exists = fs::exists(run.run_db_path);
  storage::RunDb db = exists ? storage::RunDb::open(run.run_db_path)
                             : storage::RunDb::create(run.run_db_path, recording_meta(run));
  // Where the file leaves off: the resume point after a restart.
  run.last_t_ns = db.last_frame_t_ns();
  run.last_temp_t_ns = db.last_temperature_t_ns();
  run.frames = db.frame_count();
  if (hooks.on_open) hooks.on_open(db, run.recorder_opens);
  ++run.recorder_opens;

  storage::RecorderOptions options;
  options.commit_interval_s = config_.recorder.commit_interval_s;
  options.queue_capacity_frames = config_.recorder.queue_frames;
  options.wait_when_full = hooks.wait_when_full.value_or(run.bench->paced_by_consumer());
  run.recorder_waits = options.wait_when_full;
  run.recorder_failed = false;
  {
    std::lock_guard lock(run.alarm_mutex);
    run.alarms.clear();
  }
  run.recorder = std::make_unique<storage::Recorder>(
      std::move(db), options,
      [&run](const storage::RecorderAlarm& alarm) {
        std::lock_guard lock(run.alarm_mutex);
        run.alarms.push_back(alarm);
      },
      [&run, after = hooks.after_commit](const storage::RecorderStats& s) {
        EstimatorWorker* worker = run.worker.load();
        if (worker != nullptr && s.committed_t_ns) worker->committed(*s.committed_t_ns);
        if (after) after(s);
      });
}

// The recorder's alarms since the last call, each an alarm event of the run. Returns why the run
// must suspend: the writer falls behind a device that cannot wait, dropped frames, or failed.
std::optional<std::string> Sequencer::recorder_problem(RunContext& run) {
  std::vector<storage::RecorderAlarm> alarms;
  {
    std::lock_guard lock(run.alarm_mutex);
    alarms.swap(run.alarms);
  }
  // The most serious one names the suspension: a write failure, then dropped frames, then a high
  // queue.
  std::optional<std::string> reason;
  int severity = 0;
  auto raise_reason = [&](int level, std::string why) {
    if (level > severity) {
      severity = level;
      reason = std::move(why);
    }
  };
  for (const auto& alarm : alarms) {
    // A producer that waits for room loses nothing: a high queue is then the intended pacing.
    if (alarm.kind == storage::RecorderAlarmKind::QueueHighWater && run.recorder_waits) continue;
    char counts[160];
    std::snprintf(counts, sizeof counts, " (queue high-water mark %lld of %lld frames, %lld frames dropped)",
                  static_cast<long long>(alarm.stats.high_water_frames),
                  static_cast<long long>(alarm.stats.queue_capacity_frames),
                  static_cast<long long>(alarm.stats.dropped_frames));
    note_event(run, "alarm", std::string("recorder ") + storage::to_string(alarm.kind) + ": " + alarm.message + counts);
    switch (alarm.kind) {
      case storage::RecorderAlarmKind::QueueHighWater:
        raise_reason(1, "the recorder falls behind: its queue passed its high-water level");
        break;
      case storage::RecorderAlarmKind::FramesDropped:
        raise_reason(2, "the recorder fell behind and dropped frames");
        break;
      case storage::RecorderAlarmKind::WriteHeld:
        // The recorder holds what it could not write and tries again; the run waits for it.
        raise_reason(3, alarm.message);
        break;
      case storage::RecorderAlarmKind::WriteFailed:
        run.recorder_failed = true;
        raise_reason(4, "recording failed: " + alarm.message);
        break;
    }
  }
  return reason;
}

bool Sequencer::commit_recording(RunContext& run) {
  if (run.recorder->commit_and_wait()) return true;
  if (run.recorder->error()) run.recorder_failed = true;  // reopened before the run goes on
  return false;
}

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
  if (!retry_db_writes()) {
    std::lock_guard lock(db_writes_mutex_);
    for (const auto& write : deferred_writes_) spdlog::error("daemon database: not stored at shutdown: {}", write.first);
    deferred_writes_.clear();  // their listeners may be gone after this
  }
}

json Sequencer::telemetry() const {
  std::lock_guard lock(telemetry_mutex_);
  return telemetry_;
}

json Sequencer::active_estimators() const {
  std::lock_guard lock(telemetry_mutex_);
  return estimators_;
}

std::optional<std::int64_t> Sequencer::active_id() const {
  std::lock_guard lock(mutex_);
  return active_id_;
}

RunState Sequencer::active_state() const {
  std::lock_guard lock(mutex_);
  return active_state_;
}

void Sequencer::emit(const json& event) {
  if (listener_) listener_(event);
}

bool Sequencer::transition(std::int64_t id, RunState to, const std::string& reason, std::optional<RunState> expected) {
  RunState from;
  {
    std::lock_guard lock(mutex_);
    const bool active = active_id_ == id;
    if (active) {
      if (expected && active_state_ != *expected) return false;
      from = active_state_;
      if (!store_state(id, to, reason, std::nullopt)) return false;
      active_state_ = to;
    } else {
      auto row = db_.campaign(id);
      if (!row) return false;
      from = row->state;
      if (!store_state(id, to, reason, expected)) return false;
    }
  }
  cv_.notify_all();
  spdlog::info("campaign {}: {} -> {} ({})", id, to_string(from), to_string(to), reason);
  emit({{"type", "event"}, {"campaign", id}, {"kind", "transition"}, {"from", to_string(from)},
        {"to", to_string(to)}, {"reason", reason}});
  transition_alarms(id, from, to, reason);
  return true;
}

void Sequencer::transition_alarms(std::int64_t id, RunState from, RunState to, const std::string& reason) {
  // An alarm that cannot be stored must not stop the run that raised it: it is in the log.
  try {
    write_db("the alarms of campaign " + std::to_string(id) + "'s " + std::string(to_string(from)) + " -> " +
                 std::string(to_string(to)),
             [this, id, from, to, reason] {
               for (const json& message : apply_transition_alarms(db_, id, from, to, reason)) emit(message);
             });
  } catch (const std::exception& e) {
    spdlog::error("campaign {}: alarms of {} -> {} not stored: {}", id, to_string(from), to_string(to), e.what());
  }
}

void Sequencer::record_event(std::int64_t id, const std::string& kind, std::optional<std::int64_t> segment,
                             std::optional<double> program_time_s, const std::string& reason) {
  try {
    write_db("campaign " + std::to_string(id) + "'s event '" + kind + "'",
             [this, id, kind, segment, program_time_s, reason] { db_.add_event(id, kind, segment, program_time_s, reason); });
    const auto severity = alarm_severity_of_event(kind);
    if (!severity) return;
    // Shown to the operators once stored (with a full disk: when the disk takes it again); the
    // event and the run's state say it meanwhile.
    write_db("campaign " + std::to_string(id) + "'s alarm '" + reason + "'",
             [this, id, severity = *severity, kind, segment, program_time_s, reason] {
               emit(alarm_message("raised", db_.raise_alarm(id, severity, kind, reason, segment, program_time_s)));
             });
  } catch (const std::exception& e) {
    spdlog::error("campaign {}: event or alarm '{}' not stored: {}", id, reason, e.what());
  }
}

bool Sequencer::write_db(const std::string& what, std::function<void()> write) {
  std::lock_guard lock(db_writes_mutex_);
  if (deferred_writes_.empty()) {
    try {
      write();
      return true;
    } catch (const storage::sql::SqliteError& e) {
      spdlog::error("daemon database: {} kept in memory, to be stored when the database can be written: {}", what,
                    e.what());
    }
  }
  // A bound on what a disk that stays full can make the daemon keep: beyond it the oldest
  // deferred writes are given up, each in the log (events and counters; never more than a
  // handful of state changes are among them).
  constexpr std::size_t kMaxDeferred = 100'000;
  if (deferred_writes_.size() >= kMaxDeferred) {
    spdlog::error("daemon database: {} given up: {} writes wait already", deferred_writes_.front().first, kMaxDeferred);
    deferred_writes_.pop_front();
  }
  deferred_writes_.emplace_back(what, std::move(write));
  return false;
}

std::size_t Sequencer::deferred_writes() const {
  std::lock_guard lock(db_writes_mutex_);
  return deferred_writes_.size();
}

bool Sequencer::store_state(std::int64_t id, RunState to, const std::string& reason, std::optional<RunState> expected) {
  {
    std::lock_guard lock(db_writes_mutex_);
    if (deferred_writes_.empty()) {
      try {
        return db_.set_state(id, to, reason, expected);
      } catch (const storage::sql::SqliteError& e) {
        spdlog::error("daemon database: campaign {} -> {} kept in memory, to be stored when the database can be "
                      "written: {}", id, to_string(to), e.what());
      }
    }
  }
  // The sequencer's state is the truth meanwhile; the database follows in order. A transition
  // the database refuses when it is stored at last is in the log.
  write_db("campaign " + std::to_string(id) + " -> " + std::string(to_string(to)), [this, id, to, reason] {
    if (!db_.set_state(id, to, reason))
      spdlog::error("daemon database: campaign {} -> {} refused when stored late", id, to_string(to));
  });
  return true;
}

bool Sequencer::retry_db_writes() {
  std::lock_guard lock(db_writes_mutex_);
  while (!deferred_writes_.empty()) {
    try {
      deferred_writes_.front().second();
    } catch (const storage::sql::SqliteError& e) {
      return false;  // still full: the next call tries again
    } catch (const std::exception& e) {
      spdlog::error("daemon database: {} given up: {}", deferred_writes_.front().first, e.what());
    }
    deferred_writes_.pop_front();
    if (deferred_writes_.empty()) spdlog::info("daemon database: every deferred write is stored");
  }
  return true;
}

namespace {
void sync_run_record(DaemonDb& db, RunContext& run) {
  if (!run.recorder) return;
  json record = {{"campaign_id", run.id}, {"name", run.spec.name}, {"transitions", json::array()},
                 {"events", json::array()}};
  const std::vector<TransitionRow> transitions = db.transitions(run.id);
  const std::vector<EventRow> events = db.events(run.id);
  for (const auto& t : transitions)
    record["transitions"].push_back({{"t", iso8601_utc(t.t_ms)},
                                     {"from", t.from ? json(to_string(*t.from)) : json(nullptr)},
                                     {"to", to_string(t.to)},
                                     {"reason", t.reason}});
  for (const auto& e : events)
    record["events"].push_back({{"t", iso8601_utc(e.t_ms)},
                                {"kind", e.kind},
                                {"segment", e.segment ? json(*e.segment) : json(nullptr)},
                                {"program_time_s", e.program_time_s ? json(*e.program_time_s) : json(nullptr)},
                                {"reason", e.reason}});
  const storage::RecorderStats rs = run.recorder->stats();
  record["recorder"] = {{"queue_capacity_frames", rs.queue_capacity_frames},
                        {"queue_high_water_frames", rs.high_water_frames},
                        {"dropped_frames", rs.dropped_frames}};
  // In the run file too, so that the run's own record tells every interruption; its faulted
  // intervals as the exported bundle's meta.json lists them.
  run.recorder->set_extra("imucald_run", record.dump());
  run.recorder->set_extra(storage::kFaultedIntervalsKey, faulted_intervals(transitions, events).dump());
}
}  // namespace

void Sequencer::note_event(RunContext& run, const std::string& kind, const std::string& reason) {
  record_event(run.id, kind, static_cast<std::int64_t>(run.segment), run.program_time_s, reason);
  if (kind == "alarm" || kind == "error") {
    spdlog::warn("campaign {}: {}: {}", run.id, kind, reason);
  } else {
    spdlog::info("campaign {}: {}: {}", run.id, kind, reason);
  }
  emit({{"type", "event"}, {"campaign", run.id}, {"kind", kind}, {"reason", reason},
        {"segment", run.segment}, {"program_time_s", run.program_time_s}});
  sync_run_record(db_, run);
}

Sequencer::CommandOutcome Sequencer::command(std::int64_t id, Command command, const std::string& who,
                                             const std::string& reason) {
  const std::string why = std::string(to_string(command)) + " by " + who + (reason.empty() ? "" : ": " + reason);
  std::optional<json> event;
  CommandOutcome out;
  RunState from = RunState::Created;
  {
    std::lock_guard lock(mutex_);
    if (shutdown_) return {503, "the daemon is shutting down", std::nullopt};
    const bool active = active_id_ == id;
    // The active run's state is the sequencer's, and its change is stored in order with the ones
    // a full disk kept back (an operator can stop or abort a run suspended on a full disk);
    // another campaign's state is the database's, which must first hold every change kept back.
    if (!active && !retry_db_writes())
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
    const bool stored = active ? store_state(id, *target, why, std::nullopt) : db_.set_state(id, *target, why);
    if (!stored) return {409, "campaign " + std::to_string(id) + " changed meanwhile", state};
    if (active) active_state_ = *target;
    if (*target == RunState::Queued) {
      if (state == RunState::Interrupted) {
        db_.queue_push_front(id);
      } else {
        db_.queue_push_back(id);
      }
      queue_enabled_ = true;
    }
    if (*target == RunState::Aborted && !active) db_.queue_remove(id);  // an active run is in no queue
    event = json{{"type", "event"}, {"campaign", id}, {"kind", "transition"}, {"from", to_string(state)},
                 {"to", to_string(*target)}, {"reason", why}};
    out.state = *target;
    from = state;
  }
  cv_.notify_all();
  spdlog::info("campaign {}: {}", id, why);
  if (event) emit(*event);
  if (out.state) transition_alarms(id, from, *out.state, why);
  return out;
}

std::optional<Sequencer::Outcome> Sequencer::pending_command() {
  std::lock_guard lock(mutex_);
  if (shutdown_) return Outcome::Shutdown;
  switch (active_state_) {
    case RunState::Pausing: return Outcome::Pause;
    case RunState::Stopping: return Outcome::Stop;
    case RunState::Aborting: return Outcome::Abort;
    default: return std::nullopt;
  }
}

// ------------------------------------------------------------------------------------------------
// The queue runner

void Sequencer::runner() {
  std::unique_lock lock(mutex_);
  while (!shutdown_) {
    lock.unlock();
    const bool stored = retry_db_writes();
    lock.lock();
    std::vector<std::int64_t> queue;
    std::int64_t id = 0;
    std::string reason;
    // A database that cannot be read or written (disk full) starts nothing: the queue waits.
    try {
      cv_.wait_for(lock, std::chrono::milliseconds(500), [&] {
        if (shutdown_) return true;
        if (!queue_enabled_ || !stored) return false;
        queue = db_.queue();
        return !queue.empty();
      });
      if (shutdown_) break;
      if (!queue_enabled_ || queue.empty()) continue;
      id = queue.front();
      const auto row = db_.campaign(id);
      if (!row || row->state != RunState::Queued) {
        db_.queue_remove(id);
        continue;
      }
      reason = row->run_db.empty() ? "devices free: starting" : "resuming from the last checkpoint";
      if (!db_.set_state(id, RunState::Running, reason, RunState::Queued)) continue;
      db_.queue_remove(id);
    } catch (const std::exception& e) {
      spdlog::error("the queue waits: {}", e.what());
      cv_.wait_for(lock, std::chrono::seconds(1), [&] { return shutdown_; });
      continue;
    }
    active_id_ = id;
    active_state_ = RunState::Running;
    lock.unlock();
    spdlog::info("campaign {}: queued -> running ({})", id, reason);
    emit({{"type", "event"}, {"campaign", id}, {"kind", "transition"}, {"from", "queued"}, {"to", "running"},
          {"reason", reason}});
    transition_alarms(id, RunState::Queued, RunState::Running, reason);
    try {
      run_campaign(id);
    } catch (const std::exception& e) {
      // run_campaign handles its own failures; this is the last line of defence, and must not
      // throw itself: the database it writes to may be on the disk that failed (each write is
      // kept in memory and stored later, see write_db).
      const std::string why = e.what();
      spdlog::critical("campaign {}: unexpected error: {}", id, why);
      try {
        write_db("campaign " + std::to_string(id) + "'s error", [this, id, why] { db_.set_error(id, why); });
        record_event(id, "error", std::nullopt, std::nullopt, "internal error: " + why);
        transition(id, RunState::Failed, "internal error: " + why, std::nullopt);
      } catch (const std::exception& again) {
        spdlog::critical("campaign {}: its failure not stored: {}", id, again.what());
      }
    }
    lock.lock();
    active_id_.reset();
    {
      std::lock_guard tlock(telemetry_mutex_);
      telemetry_["run"] = nullptr;
      estimators_ = json::object();
      telemetry_["estimators"] = estimators_;
    }
  }
}

// ------------------------------------------------------------------------------------------------
// One run

// The run file (created on the first start, reopened to resume), its recorder and the estimators
// that tail it. Returns whether the run resumes an earlier one.
bool Sequencer::open_run(RunContext& run) {
  // The run file: created on the first start, reopened to resume.
  const std::string relative = "runs/" + std::to_string(run.id) + ".db";
  run.run_db_path = (fs::path(config_.data_dir) / relative).string();
  fs::create_directories(fs::path(run.run_db_path).parent_path());
  const bool resuming = fs::exists(run.run_db_path);
  if (!resuming)
    write_db("campaign " + std::to_string(run.id) + "'s run file", [this, id = run.id, relative] { db_.set_run_db(id, relative); });
  open_recorder(run);
  const auto committed_t = run.last_t_ns;
  // A resumed run's faults up to what is committed fired in the process that recorded it.
  if (committed_t) run.bench->resuming_after(static_cast<double>(*committed_t) / units::kNsPerS);
  EstimatorWorker::Spec estimators = estimator_spec(run.spec, db_);
  run.estimators = std::make_unique<EstimatorWorker>(
      run.run_db_path, std::move(estimators), committed_t,
      [this, id = run.id](const std::string& name, double t_s, const json& progress) { store_progress(id, name, t_s, progress); });
  run.worker = run.estimators.get();
  return resuming;
}

// An estimator's progress (on the worker thread): the live telemetry's and the database's.
void Sequencer::store_progress(std::int64_t id, const std::string& name, double t_s, const json& progress) {
  json all;
  {
    std::lock_guard lock(telemetry_mutex_);
    estimators_[name] = progress;
    all = estimators_;
  }
  try {
    db_.add_progress(id, name, t_s, progress.dump());
    db_.set_estimators(id, all.dump());
  } catch (const std::exception& e) {
    spdlog::error("campaign {}: cannot store estimator progress: {}", id, e.what());
  }
}

// The program from the run's checkpoint to its end (or to the command or fault that ends it):
// segment after segment, pausing, holding and redoing as the state machine says.
Sequencer::Outcome Sequencer::run_program(RunContext& run) {
  Outcome outcome = prepare_devices(run);
  for (;;) {
    if (outcome == Outcome::Pause) {
      outcome = paused(run);  // Redo on resume
      continue;
    }
    if (outcome != Outcome::Completed && outcome != Outcome::Redo) break;
    if (run.segment >= run.segments.size()) {
      // The last frames are in the file before the run is done: a write that fails at the end
      // (a full disk found only by the final commit on a loaded machine) suspends the run and
      // redoes what was lost, as anywhere else in the program.
      if (run.recorder && !commit_recording(run)) {
        outcome = hold(run, run.recorder->write_problem().value_or(
                                "recording failed: " + run.recorder->error().value_or("write failed")));
        continue;
      }
      outcome = Outcome::Completed;
      break;
    }
    write_db("campaign " + std::to_string(run.id) + "'s checkpoint",
             [this, id = run.id, segment = static_cast<std::int64_t>(run.segment), t_s = run.checkpoint_s()] {
               db_.set_checkpoint(id, segment, t_s);
             });
    if (run.segments[run.segment].kind == "power-cycle" && run.power_cycled_segment != run.segment) {
      outcome = await_power_cycle(run);
      if (outcome != Outcome::Completed) continue;
    }
    outcome = run_segment(run);
    if (outcome == Outcome::Completed) ++run.segment;
  }
  return outcome;
}

void Sequencer::run_campaign(std::int64_t id) {
  RunContext run;
  run.id = id;
  auto fail_early = [&](const std::string& why) {
    write_db("campaign " + std::to_string(id) + "'s error", [this, id, why] { db_.set_error(id, why); });
    record_event(id, "error", std::nullopt, std::nullopt, why);
    transition(id, RunState::Failed, why, std::nullopt);
  };
  const auto row = db_.campaign(id);
  if (!row) return;
  run.row = *row;
  // A resumed run counts on from what it had counted (lost and bad frames as last stored; the
  // frames from the run file): before issue 33 a restart set both back to zero.
  run.lost = row->lost_frames;
  run.bad = row->bad_frames;
  {
    const CampaignCheck check = check_campaign_text(row->spec_json, config_);
    if (!check.spec) {
      std::string why = "the campaign is no longer valid with this configuration:";
      for (const auto& p : check.problems) why += " " + p + ";";
      fail_early(why);
      return;
    }
    run.spec = *check.spec;
  }
  run.suspenders = std::make_unique<Suspenders>(run.spec.suspenders);
  try {
    run.program = compile_campaign_program(run.spec, config_);
    run.segments = run.program.segments();
    if (run.segments.empty()) throw std::runtime_error("the program has no segments");
    run.dt_ns = std::llround(units::kNsPerS / run.spec.rate_hz);

    run.bench = make_bench(config_, run.spec, run.program, storage_disk_switch());
    check_unit(run);

    const bool resuming = open_run(run);
    run.place_at_committed();
    note_event(run, "info", run.bench->describe() + "; " + std::to_string(run.segments.size()) + " segments, " +
                                std::to_string(run.program.duration_s()) + " s");
    if (resuming) {
      char text[256];
      std::snprintf(text, sizeof text,
                    "resuming after an interruption: %lld frames committed up to %.3f s; redoing segment %zu from "
                    "its start at %.3f s",
                    static_cast<long long>(run.frames), run.program_time_s, run.segment, run.checkpoint_s());
      note_event(run, "redo", text);
    }

    finish_run(run, run_program(run), "");
  } catch (const std::exception& e) {
    const std::string why = e.what();
    spdlog::error("campaign {}: {}", id, why);
    write_db("campaign " + std::to_string(id) + "'s error", [this, id, why] { db_.set_error(id, why); });
    if (run.bench) {
      note_event(run, "error", why);
      finish_run(run, Outcome::Fail, why);
    } else {
      fail_early(why);
    }
  }
}

Sequencer::Outcome Sequencer::prepare_devices(RunContext& run) {
  Table& table = run.bench->table();
  if (!table.state().homed) {
    if (auto r = table.home(); !r.ok) throw std::runtime_error("homing the table failed: " + r.message);
    note_event(run, "homed", "table homed");
  }
  if (auto r = table.close_interlock(); !r.ok) throw std::runtime_error("closing the table interlock failed: " + r.message);
  return wait_until_ready(run, false);
}

// Before the table moves (start, redo): the chamber at the profile's set point of the
// checkpoint, every device answering. After a suspension the condition must stay clear for the
// settle time; at the start the chamber only has to be in its band.
// What the suspenders look at: the devices' states now, against the chamber band given.
DeviceReadings Sequencer::readings(RunContext& run, double setpoint_C, double tolerance_C) {
  DeviceReadings r;
  r.now_s = run.bench->now_s();
  const TableState ts = run.bench->table().state();
  r.table_connected = ts.connected;
  r.table_fault = ts.fault;
  const ChamberState cs = run.bench->chamber().state();
  r.chamber_connected = cs.connected;
  r.chamber_C = cs.temperature_C;
  r.setpoint_C = setpoint_C;
  r.tolerance_C = tolerance_C;
  r.imu_connected = run.bench->imu().state().connected;
  r.last_frame_s = run.last_frame_world_s;
  // A recorder that holds frames it cannot write keeps the run held until it has written them.
  if (run.recorder) r.recorder_problem = run.recorder->write_problem().value_or("");
  return r;
}

Sequencer::Outcome Sequencer::wait_until_ready(RunContext& run, bool suspended) {
  const double setpoint_C = run.spec.chamber.setpoint_at(run.checkpoint_s());
  const double tolerance_C = run.spec.chamber.tolerance_C;
  const double settle_s = suspended ? run.spec.suspenders.settle_s : 0.0;
  const double start_s = run.bench->now_s();
  std::optional<double> clear_since_s;
  bool announced = false;
  for (;;) {
    if (auto c = pending_command()) return *c;
    if (!run.commanded_setpoint_C || std::abs(*run.commanded_setpoint_C - setpoint_C) > 1e-9) {
      if (run.bench->chamber().set_setpoint(setpoint_C).ok) run.commanded_setpoint_C = setpoint_C;
    }
    const DeviceReadings r = readings(run, setpoint_C, tolerance_C);
    const bool clear = run.suspenders->clear(r);
    const double now_s = r.now_s;
    if (clear) {
      if (!clear_since_s) clear_since_s = now_s;
      if (now_s - *clear_since_s >= settle_s) break;
    } else {
      clear_since_s.reset();
      if (!suspended && !announced) {
        note_event(run, "info", "waiting for the chamber to reach " + celsius_text(setpoint_C) + " (now " +
                                    celsius_text(r.chamber_C) + ") before moving");
        announced = true;
      }
      if (!suspended && now_s - start_s > config_.chamber.wait_timeout_s)
        throw std::runtime_error("the chamber did not reach its set point within " +
                                 number_text(config_.chamber.wait_timeout_s) + " s");
    }
    run.bench->wait(0.1);
    // As fast as possible still must not spin a core while nothing changes.
    if (run.bench->time_scale() <= 0.0) std::this_thread::sleep_for(std::chrono::milliseconds(1));
    publish(run, false);
  }
  return Outcome::Completed;
}

namespace {

// The pieces of Sequencer::run_segment's loop, one step each (small functions also keep
// clang-tidy's optional-access analysis fast: it runs per function, and its cost grows steeply
// with the branches on optionals in one function; run_segment whole took minutes).

// The chamber's setpoint for the program's time, sent when it changed.
void command_setpoint(RunContext& run) {
  const double setpoint_C = run.spec.chamber.setpoint_at(run.program_time_s);
  if (!run.commanded_setpoint_C || std::abs(*run.commanded_setpoint_C - setpoint_C) > 1e-3) {
    if (run.bench->chamber().set_setpoint(setpoint_C).ok) run.commanded_setpoint_C = setpoint_C;
  }
}

// Whether an instant follows the last one handed to the recorder (`last`, none yet: it does);
// when it does, it becomes the last. The optionals of take_frames and take_temperatures are
// touched here only: the optional analysis of a function over the whole RunContext, in a loop,
// took minutes.
bool follows_last(std::optional<std::int64_t>& last, std::int64_t t_ns) {
  if (last && t_ns <= *last) return false;
  last = t_ns;
  return true;
}

// The frames of `batch` as delivered, checked (finite values, time increasing on the frame grid):
// those to record into `accepted`; what was wrong with the first bad one ("" when none was).
std::string take_frames(RunContext& run, const FrameBatch& batch, bool last, std::int64_t end_ns,
                        std::vector<ImuFrame>& accepted) {
  accepted.clear();
  for (const ImuFrame& f : batch.frames) {
    const bool finite = f.dtheta_rad.allFinite() && f.dv_mps.allFinite() && f.table_deg.allFinite();
    if (!finite || f.t_ns <= run.prev_delivered_t_ns) {
      ++run.bad;
      return "corrupt IMU frame at " + number_text(static_cast<double>(f.t_ns) / units::kNsPerS) + " s";
    }
    const std::int64_t step_ns = f.t_ns - run.prev_delivered_t_ns;
    if (2 * step_ns > 3 * run.dt_ns) {
      const std::int64_t missing = (step_ns + run.dt_ns / 2) / run.dt_ns - 1;
      run.lost += missing;
      return std::to_string(missing) + " IMU frame(s) missing before " +
             number_text(static_cast<double>(f.t_ns) / units::kNsPerS) + " s";
    }
    run.prev_delivered_t_ns = f.t_ns;
    ++run.delivered;
    // The program's grid ends at its last instant: in the last segment the IMU goes on
    // delivering (the sequencer waits for the table to come to rest, and a loaded machine may
    // hand over frames past the end in one batch); those are not part of the run.
    if (last && f.t_ns > end_ns) continue;
    if (follows_last(run.last_t_ns, f.t_ns)) accepted.push_back(f);
  }
  return {};
}

// The temperatures of `batch` up to the frames accepted so far, each once, into `temps`.
void take_temperatures(RunContext& run, const FrameBatch& batch, std::vector<TempSample>& temps) {
  temps.clear();
  for (const TempSample& t : batch.temps) {
    if (t.t_ns > run.prev_delivered_t_ns + run.dt_ns) break;  // beyond the frames accepted so far
    if (follows_last(run.last_temp_t_ns, t.t_ns)) temps.push_back(t);
  }
}

// The accepted frames to the recorder; why they are not all recorded ("" when they are). The run's
// counters and last frame are passed alone, not the RunContext (see follows_last).
std::string record_frames(storage::Recorder& recorder, const std::vector<ImuFrame>& accepted, std::int64_t& frames,
                          std::int64_t& lost, std::optional<std::int64_t>& last_t_ns) {
  frames += static_cast<std::int64_t>(accepted.size());
  const auto pushed = recorder.push(accepted);
  if (pushed == storage::Recorder::Push::Rejected)
    throw std::runtime_error("internal error: the recorder refused frames that do not follow the recorded ones");
  if (pushed == storage::Recorder::Push::Refused) {
    // The run file cannot be written now: the recorder holds what it took and took nothing
    // after it. The frames it refused are not recorded yet; the redo of the segment after
    // the suspension records them (it records only frames after the last one taken).
    const std::optional<std::int64_t> taken = recorder.last_accepted_t_ns();
    std::int64_t refused = 0;
    for (const ImuFrame& f : accepted)
      if (!taken || f.t_ns > *taken) ++refused;
    frames -= refused;
    last_t_ns = taken;
    return recorder.write_problem().value_or("the recorder refused frames");
  }
  if (pushed == storage::Recorder::Push::Dropped) {
    // Counted in the run file too (recorder_session, dropped_span); those instants stay a gap.
    lost += static_cast<std::int64_t>(accepted.size());
    return "the recorder fell behind and dropped frames";
  }
  return {};
}

}  // namespace

Sequencer::Outcome Sequencer::run_segment(RunContext& run) {
  const std::size_t k = run.segment;
  const bool last = k + 1 == run.segments.size();
  const std::int64_t end_ns = run.segment_end_ns(k);
  const std::int64_t until_ns = last ? std::numeric_limits<std::int64_t>::max() : end_ns;
  const double t0_s = run.segments[k].t0_s;

  // After a pause during a suspension for a failed run file.
  if (!run.recorder || run.recorder_failed) return hold(run, "recording failed: the run file is not open for writing");
  // After a safe hold the interlock is open: close it before the table moves again.
  if (!run.bench->table().state().interlock_closed) {
    if (auto r = run.bench->table().close_interlock(); !r.ok) return hold(run, "table interlock: " + r.message);
  }
  if (auto r = run.bench->table().start_program_at(t0_s); !r.ok) return hold(run, "table: " + r.message);
  run.prev_delivered_t_ns = std::llround(t0_s * units::kNsPerS);
  run.last_frame_world_s = run.bench->now_s();
  run.suspenders->reset();

  FrameBatch batch;
  std::vector<ImuFrame> accepted;
  std::vector<TempSample> temps;
  for (;;) {
    if (auto c = pending_command()) return *c;
    command_setpoint(run);
    if (auto r = run.bench->imu().read(batch, until_ns); !r.ok) return hold(run, "IMU: " + r.message);

    std::string problem = take_frames(run, batch, last, end_ns, accepted);
    if (!batch.frames.empty()) {
      run.last_frame_world_s = run.bench->now_s();
      run.program_time_s = static_cast<double>(run.prev_delivered_t_ns) / units::kNsPerS;
    }
    take_temperatures(run, batch, temps);
    if (!accepted.empty()) {
      if (std::string why = record_frames(*run.recorder, accepted, run.frames, run.lost, run.last_t_ns); !why.empty())
        problem = std::move(why);
    }
    if (!temps.empty()) (void)run.recorder->push_temps(temps);  // a failure shows as an alarm below

    // Suspenders (daemon/run/suspenders.*): the recorder, the frames, the devices.
    DeviceReadings r = readings(run, run.spec.chamber.setpoint_at(run.program_time_s), run.spec.chamber.tolerance_C);
    if (auto why = recorder_problem(run)) {
      r.recorder_problem = *why;
    } else if (auto held = run.recorder->write_problem()) {
      r.recorder_problem = *held;
    } else if (auto error = run.recorder->error()) {  // before its alarm has arrived
      run.recorder_failed = true;
      r.recorder_problem = "recording failed: " + *error;
    }
    r.frame_problem = problem;
    if (const auto trip = run.suspenders->trip(r)) {
      if (trip->suspender == "imu-frames-missing") ++run.lost;  // at least one; the exact count shows as a gap
      return hold(run, trip->reason);
    }

    publish(run, false);
    const bool reached_end = run.prev_delivered_t_ns > end_ns - run.dt_ns;
    if (reached_end && (!last || !run.bench->table().state().moving)) return Outcome::Completed;
  }
}

// Safe hold after a suspender tripped: the table stops where it is, the recorder commits, and the
// run waits until every condition is clear for the settle time, then redoes the segment.
Sequencer::Outcome Sequencer::hold(RunContext& run, const std::string& reason) {
  publish(run, true);  // the counters as they are when the condition is found
  if (!transition(run.id, RunState::Suspended, reason, RunState::Running)) {
    // An operator command arrived meanwhile; it takes precedence.
    if (auto r = run.bench->table().stop(); !r.ok) note_event(run, "alarm", "stopping the table: " + r.message);
    if (auto c = pending_command()) return *c;
    return Outcome::Redo;
  }
  note_event(run, "suspended", reason);
  safe_hold(run);
  (void)commit_recording(run);
  (void)recorder_problem(run);  // alarms raised meanwhile become events
  sync_run_record(db_, run);
  publish(run, true);
  for (;;) {
    const Outcome waited = wait_until_ready(run, true);
    if (waited != Outcome::Completed) return waited;
    if (!run.recorder_failed) break;
    // The run file failed (disk full, damaged): reopen it, which rolls back to the last commit and
    // checks it; the run then continues from the segment holding the first frame lost with the
    // failed batch. While it cannot be written the run stays suspended and tries again each
    // settle time.
    try {
      run.recorder.reset();
      // The old writer has ended: an alarm it raised after the check above is recorded now, not
      // lost when the new recorder starts with none.
      (void)recorder_problem(run);
      open_recorder(run);
      run.place_at_committed();
      char text[300];
      std::snprintf(text, sizeof text,
                    "run file reopened after the write failure: %lld frames committed up to %.3f s",
                    static_cast<long long>(run.frames), run.program_time_s);
      note_event(run, "info", text);
      if (!run.recorder->commit_and_wait())
        throw std::runtime_error(run.recorder->error().value_or(run.recorder->write_problem().value_or("write failed")));
    } catch (const std::exception& e) {
      run.recorder_failed = true;
      note_event(run, "alarm", std::string("the run file still cannot be written: ") + e.what() +
                                   "; trying again after the settle time");
    }
    (void)recorder_problem(run);
  }
  std::string text = "condition cleared and settled " + number_text(run.spec.suspenders.settle_s) + " s; ";
  if (run.segment >= run.segments.size()) {
    // The file holds every frame of the program (what failed came after the last one).
    text += "every frame of the program is in the run file";
  } else {
    const bool ramp = run.spec.chamber.ramps_within(run.segments[run.segment].t0_s, run.segments[run.segment].t1_s);
    text += "redoing segment " + std::to_string(run.segment) + " '" + run.segments[run.segment].name + "' from " +
            number_text(run.checkpoint_s()) + " s" +
            (ramp ? " (not redoable as it was: it overlaps a chamber ramp, which restarts from the checkpoint's set point)"
                  : "");
  }
  // The transition says what cleared; the UI says "resumed" itself.
  if (!transition(run.id, RunState::Running, reason + " cleared", RunState::Suspended)) {
    if (auto c = pending_command()) return *c;
  }
  note_event(run, "resumed", text);
  return Outcome::Redo;
}

// Operator pause: table stopped, recorder committed, then wait for resume, stop or abort.
Sequencer::Outcome Sequencer::paused(RunContext& run) {
  safe_hold(run);
  if (run.recorder) (void)commit_recording(run);  // a failed file is reopened on resume
  // The counters first: whoever sees "paused" must see where the run holds.
  publish(run, true);
  if (!transition(run.id, RunState::Paused, "table stopped, recording committed", RunState::Pausing)) {
    if (auto c = pending_command()) return *c;
  }
  note_event(run, "paused", "paused in segment " + std::to_string(run.segment) + " '" +
                                run.segments[run.segment].name + "'");
  publish(run, true);
  for (;;) {
    {
      std::unique_lock lock(mutex_);
      cv_.wait_for(lock, std::chrono::milliseconds(100), [&] { return shutdown_ || active_state_ != RunState::Paused; });
    }
    if (auto c = pending_command()) return *c;
    if (active_state() == RunState::Running) break;
    publish(run, false);
  }
  const Outcome waited = wait_until_ready(run, false);
  if (waited != Outcome::Completed) return waited;
  note_event(run, "resumed", "redoing segment " + std::to_string(run.segment) + " '" + run.segments[run.segment].name +
                                 "' from " + number_text(run.checkpoint_s()) + " s");
  return Outcome::Redo;
}

Sequencer::Outcome Sequencer::await_power_cycle(RunContext& run) {
  // The table at rest with its interlock open: the operator may reach the IMU and its cable.
  safe_hold(run);
  if (run.recorder) (void)commit_recording(run);
  const SegmentInfo& seg = run.segments[run.segment];
  std::string text = "Power-cycle the IMU: switch it off, wait at least 10 s, switch it on, then answer Done. "
                     "Segment " + std::to_string(run.segment + 1) + " '" + seg.name + "' starts after the answer.";
  if (PowerSwitch* power = run.bench->power_switch()) {
    std::string failure;
    if (const auto switched = switch_power(run, *power, failure)) return *switched;
    note_event(run, "alarm", failure + "; asking the operator instead");
    text += " (The power relay failed: " + failure + ".)";
  }
  {
    std::lock_guard lock(mutex_);
    prompt_ = Prompt{run.id, run.segment, text, iso8601_utc(now_unix_ms()), std::nullopt};
  }
  note_event(run, "prompt", text);
  publish(run, true);
  std::string who;
  for (;;) {
    {
      std::unique_lock lock(mutex_);
      cv_.wait_for(lock, std::chrono::milliseconds(100), [&] {
        return shutdown_ || active_state_ != RunState::Running || (prompt_ && prompt_->answered_by);
      });
      if (prompt_ && prompt_->answered_by) {
        who = *prompt_->answered_by;
        prompt_.reset();
        break;
      }
    }
    if (auto c = pending_command()) {
      std::lock_guard lock(mutex_);
      prompt_.reset();  // asked again when the run comes back to this segment
      return *c;
    }
    publish(run, false);
  }
  run.power_cycled_segment = run.segment;
  note_event(run, "prompt-answered", "the IMU was power-cycled (answered by " + who + ")");
  publish(run, true);
  return wait_until_ready(run, false);
}

// The IMU power-cycled through the bench's relay: off, off_s on the bench's clock, on. A command
// meanwhile (pause, stop) still has the IMU switched on again first: every way out of a run
// leaves it powered. nullopt, with `failure`, when a switch failed.
std::optional<Sequencer::Outcome> Sequencer::switch_power(RunContext& run, PowerSwitch& power, std::string& failure) {
  if (auto r = power.set_power(false); !r.ok) {
    failure = r.message;
    return std::nullopt;
  }
  const double off_since_s = run.bench->now_s();
  note_event(run, "power-off",
             "the IMU switched off through " + power.describe() + "; on again in " + number_text(power.off_s()) + " s");
  publish(run, true);
  std::optional<Outcome> command;
  for (;;) {
    const double left_s = off_since_s + power.off_s() - run.bench->now_s();
    if (left_s <= 0.0 || (command = pending_command())) break;
    run.bench->wait(std::min(0.1, left_s));
    publish(run, false);
  }
  if (auto r = power.set_power(true); !r.ok) {
    failure = "switching the IMU on again: " + r.message;
    return std::nullopt;
  }
  note_event(run, "power-on",
             "the IMU switched on again after " + number_text(run.bench->now_s() - off_since_s) + " s unpowered");
  if (command) return *command;  // asked again (switched) when the run comes back to this segment
  run.power_cycled_segment = run.segment;
  publish(run, true);
  return wait_until_ready(run, false);
}

json Sequencer::prompt_of(std::int64_t id) const {
  std::lock_guard lock(mutex_);
  if (!prompt_ || prompt_->campaign != id || prompt_->answered_by) return nullptr;
  return {{"text", prompt_->text}, {"since", prompt_->since}, {"segment", prompt_->segment}};
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

// Safe hold (pause, suspension): rate zero, then the interlock open, as on every path out of
// running; the next segment closes it again before the table moves.
void Sequencer::safe_hold(RunContext& run) {
  if (auto r = run.bench->table().stop(); !r.ok) note_event(run, "alarm", "stopping the table: " + r.message);
  if (auto r = run.bench->table().open_interlock(); !r.ok) note_event(run, "alarm", "opening the interlock: " + r.message);
}

void Sequencer::safe_exit(RunContext& run) {
  if (!run.bench) return;
  // Rate zero first, then the interlock, then the chamber: the order that is safe whatever fails.
  if (auto r = run.bench->table().stop(); !r.ok) note_event(run, "alarm", "safe exit: stopping the table: " + r.message);
  if (auto r = run.bench->table().open_interlock(); !r.ok)
    note_event(run, "alarm", "safe exit: opening the interlock: " + r.message);
  if (auto r = run.bench->chamber().set_setpoint(config_.chamber.safe_setpoint_C); !r.ok)
    note_event(run, "alarm", "safe exit: chamber to its safe set point: " + r.message);
}

// The estimators' final results, once the program has ended: they may lag behind it (a fast time
// scale), so the page follows them through the tail with telemetry saying so.
void Sequencer::store_estimator_results(RunContext& run) {
  run.estimators_finishing = true;
  try {
    const EstimatorWorker::Results r = run.estimators->finish(run.last_t_ns, [&] { publish(run, false); });
    run.estimators_finishing = false;
    if (r.model)
      write_db("campaign " + std::to_string(run.id) + "'s model",
               [this, id = run.id, text = imu_model_to_json_text(*r.model)] { db_.set_model(id, text); });
    write_db("campaign " + std::to_string(run.id) + "'s results",
             [this, id = run.id, text = r.results.dump()] { db_.set_results(id, text); });
    // A recorder that failed refuses these (the model stays in the daemon's database).
    if (run.recorder) {
      run.recorder->set_extra("imucald_results", r.results.dump());
      if (r.model) run.recorder->set_extra("imucald_model", imu_model_to_json_text(*r.model));
    }
  } catch (const std::exception& e) {
    run.estimators_finishing = false;
    // A run ending on an error must still end: the error is kept with the run.
    spdlog::error("campaign {}: the estimators could not finish: {}", run.id, e.what());
    write_db("campaign " + std::to_string(run.id) + "'s results",
             [this, id = run.id,
              text = json{{"error", std::string("the estimators could not finish: ") + e.what()}}.dump()] {
               db_.set_results(id, text);
             });
  }
}

void Sequencer::finish_run(RunContext& run, Outcome outcome, const std::string& reason) {
  try {
    safe_exit(run);
  } catch (const std::exception& e) {
    spdlog::error("campaign {}: safe exit: {}", run.id, e.what());
  }
  // The parked table in the telemetry before the run is seen final: a client that reads both
  // after the final state must not see the bench as it was before the safe exit.
  publish(run, true);
  RunState final_state = RunState::Failed;
  std::string why = reason;
  bool results = false;
  switch (outcome) {
    case Outcome::Completed:
      final_state = RunState::Done;
      why = "program complete";
      results = true;
      break;
    case Outcome::Stop:
      final_state = RunState::Done;
      why = "stopped early at " + number_text(run.program_time_s) + " s; results from the data so far";
      results = true;
      break;
    case Outcome::Abort:
      // The table is parked first (safe_exit above); the estimators then finish on the data so
      // far, as for a stop: a partial run keeps its model (complete: false, counts only when an
      // operator accepts it).
      final_state = RunState::Aborted;
      why = "aborted at " + number_text(run.program_time_s) + " s; table parked, results from the data so far";
      results = true;
      break;
    case Outcome::Shutdown:
      final_state = RunState::Interrupted;
      why = "the daemon shut down; table parked, recording committed; resume continues from the last checkpoint";
      break;
    default:
      final_state = RunState::Failed;
      if (why.empty()) why = "failed";
      results = true;  // what was recorded before the failure still calibrates (partial)
      break;
  }
  // A shutdown while the recorder holds frames for want of space leaves the run interrupted: those
  // frames are lost with the process, and the resume takes up after the last commit.
  if (run.recorder && !run.recorder->commit_and_wait() && final_state != RunState::Failed &&
      !(final_state == RunState::Interrupted && !run.recorder->error())) {
    final_state = RunState::Failed;
    why = "recording failed: " + run.recorder->error().value_or(run.recorder->write_problem().value_or("unknown error"));
    write_db("campaign " + std::to_string(run.id) + "'s error", [this, id = run.id, why] { db_.set_error(id, why); });
    // Its alarm; the run record is written again below (the recorder refuses nothing more now).
    record_event(run.id, "error", static_cast<std::int64_t>(run.segment), run.program_time_s, why);
  }
  if (run.estimators) {
    if (results && is_final(final_state)) store_estimator_results(run);
    else run.estimators->cancel();
  }
  write_db("campaign " + std::to_string(run.id) + "'s counters",
           [this, id = run.id, t_s = run.program_time_s, frames = run.frames, lost = run.lost, bad = run.bad] {
             db_.update_run(id, t_s, frames, lost, bad);
           });
  if (is_final(final_state)) {
    write_db("campaign " + std::to_string(run.id) + "'s completeness",
             [this, id = run.id, complete = outcome == Outcome::Completed && final_state == RunState::Done] {
               db_.set_complete(id, complete);
             });
  }
  transition(run.id, final_state, why, std::nullopt);
  sync_run_record(db_, run);
  publish(run, true);
  if (run.recorder) (void)run.recorder->close();  // a failure was reported above
  run.worker = nullptr;
  run.recorder.reset();
  run.estimators.reset();
}

// Telemetry snapshot (at most 20 a second) and the run's counters in the database (once a second).
void Sequencer::publish(RunContext& run, bool force) {
  const auto now = Clock::now();
  if (!force && now - run.last_publish < std::chrono::milliseconds(50)) return;
  run.last_publish = now;
  const double window_s = seconds(now - run.window_wall);
  if (run.window_wall == Clock::time_point{} || window_s > 5.0) {
    run.window_wall = now;
    run.window_world_s = run.bench->now_s();
    run.window_delivered = run.delivered;
  } else if (window_s >= 0.5) {
    const double world_s = run.bench->now_s() - run.window_world_s;
    // The bench's time, not the program's: a redone segment sets the program time back (a
    // negative "speed" after a resume), the bench's clock only goes forward.
    run.speed_factor = world_s / window_s;
    run.frame_rate_hz = world_s > 0 ? static_cast<double>(run.delivered - run.window_delivered) / world_s : 0.0;
    run.window_wall = now;
    run.window_world_s = run.bench->now_s();
    run.window_delivered = run.delivered;
  }
  const TableState ts = run.bench->table().state();
  const ChamberState cs = run.bench->chamber().state();
  const storage::RecorderStats rs = run.recorder ? run.recorder->stats() : storage::RecorderStats{};
  const RunState state = active_state();
  const double duration_s = run.program.duration_s();
  const std::size_t k = std::min(run.segment, run.segments.size() - 1);
  const double band_setpoint_C = run.spec.chamber.setpoint_at(run.program_time_s);
  json t = {
      {"run",
       {{"id", run.id},
        {"name", run.spec.name},
        {"state", to_string(state)},
        {"segment", {{"index", k}, {"count", run.segments.size()}, {"name", run.segments[k].name},
                     {"kind", run.segments[k].kind}}},
        {"program_time_s", run.program_time_s},
        {"duration_s", duration_s},
        {"time_left_s", std::max(0.0, duration_s - run.program_time_s)},
        {"checkpoint_s", run.checkpoint_s()},
        {"speed_factor", run.speed_factor}}},
      {"table",
       {{"angle_deg", vec3(ts.angle_deg)}, {"rate_dps", vec3(ts.rate_dps)}, {"homed", ts.homed},
        {"interlock_closed", ts.interlock_closed}, {"connected", ts.connected},
        {"fault", ts.fault.empty() ? json(nullptr) : json(ts.fault)}}},
      {"chamber",
       {{"temperature_C", cs.temperature_C}, {"setpoint_C", cs.setpoint_C},
        {"tolerance_C", run.spec.chamber.tolerance_C},
        {"in_band", std::abs(cs.temperature_C - band_setpoint_C) <= run.spec.chamber.tolerance_C},
        {"connected", cs.connected}}},
      {"imu",
       {{"frame_rate_hz", run.frame_rate_hz}, {"frames", run.frames}, {"lost_frames", run.lost},
        {"bad_frames", run.bad}, {"connected", run.bench->imu().state().connected}}},
      {"recorder",
       {{"queue_frames", rs.queued_frames}, {"queue_high_water_frames", rs.high_water_frames},
        {"committed_frames", rs.stored_frames}, {"dropped_frames", rs.dropped_frames}}}};
  t["run"]["prompt"] = prompt_of(run.id);
  t["run"]["estimators_finishing"] = run.estimators_finishing;
  {
    std::lock_guard lock(telemetry_mutex_);
    t["estimators"] = estimators_;
    telemetry_ = std::move(t);
  }
  if (force || now - run.last_db_update >= std::chrono::seconds(1)) {
    run.last_db_update = now;
    // With a full disk the counters wait for the next second; what was deferred is tried again.
    if (retry_db_writes()) {
      try {
        db_.update_run(run.id, run.program_time_s, run.frames, run.lost, run.bad);
      } catch (const storage::sql::SqliteError& e) {
        spdlog::warn("campaign {}: counters not stored: {}", run.id, e.what());
      }
    }
  }
}

}  // namespace imucal::daemon
