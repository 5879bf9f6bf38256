#include "daemon/subscribers/run_file.hpp"

#include <filesystem>
#include <vector>

#include <nlohmann/json.hpp>
#include <spdlog/spdlog.h>

#include "daemon/campaign/campaign.hpp"
#include "daemon/subscribers/faulted_intervals.hpp"
#include "storage/bundle.hpp"
#include "storage/run_db.hpp"
#include "storage/sqlite.hpp"

namespace imucal::daemon {

using nlohmann::json;

DiskFaultSwitch storage_disk_switch() {
  return {[](bool full) { storage::disk_fault::set_full(full); }, [] { return storage::disk_fault::refused_writes(); }};
}

namespace {

RecordingStats stats_of(const storage::RecorderStats& s) {
  return {s.queued_frames, s.queue_capacity_frames, s.high_water_frames, s.stored_frames, s.dropped_frames};
}

RecordingAlarm::Kind kind_of(storage::RecorderAlarmKind kind) {
  switch (kind) {
    case storage::RecorderAlarmKind::QueueHighWater: return RecordingAlarm::Kind::QueueHighWater;
    case storage::RecorderAlarmKind::FramesDropped: return RecordingAlarm::Kind::FramesDropped;
    case storage::RecorderAlarmKind::WriteHeld: return RecordingAlarm::Kind::WriteHeld;
    case storage::RecorderAlarmKind::WriteFailed: return RecordingAlarm::Kind::WriteFailed;
  }
  return RecordingAlarm::Kind::WriteFailed;
}

RunRecording::Push push_of(storage::Recorder::Push push) {
  switch (push) {
    case storage::Recorder::Push::Queued: return RunRecording::Push::Queued;
    case storage::Recorder::Push::Dropped: return RunRecording::Push::Dropped;
    case storage::Recorder::Push::Rejected: return RunRecording::Push::Rejected;
    case storage::Recorder::Push::Failed: return RunRecording::Push::Failed;
    case storage::Recorder::Push::Refused: return RunRecording::Push::Refused;
  }
  return RunRecording::Push::Failed;
}

}  // namespace

// A run file being recorded: storage's Recorder, its alarms kept for the run loop to take.
class StorageRecording final : public RunRecording {
 public:
  StorageRecording(RunFiles& files, std::int64_t campaign, bool waits) : files_(files), campaign_(campaign), waits_(waits) {}
  ~StorageRecording() override {
    files_.forget(this);
    recorder_.reset();  // its thread ends before the alarms it may still raise go
  }
  void start(storage::RunDb db, const storage::RecorderOptions& options, std::function<void(std::int64_t)> committed,
             std::function<void(const storage::RecorderStats&)> after_commit) {
    recorder_ = std::make_unique<storage::Recorder>(
        std::move(db), options,
        [this](const storage::RecorderAlarm& alarm) {
          std::lock_guard lock(alarm_mutex_);
          alarms_.push_back({kind_of(alarm.kind), storage::to_string(alarm.kind), alarm.message, stats_of(alarm.stats)});
        },
        [committed = std::move(committed), after = std::move(after_commit)](const storage::RecorderStats& s) {
          if (s.committed_t_ns) committed(*s.committed_t_ns);
          if (after) after(s);
        });
  }

  Push push(const std::vector<ImuFrame>& frames) override { return push_of(recorder_->push(frames)); }
  bool push_temps(const std::vector<TempSample>& temps) override { return recorder_->push_temps(temps); }
  std::optional<std::int64_t> last_accepted_t_ns() const override { return recorder_->last_accepted_t_ns(); }
  bool commit_and_wait() override { return recorder_->commit_and_wait(); }
  bool close() override { return recorder_->close(); }
  RecordingStats stats() const override { return stats_of(recorder_->stats()); }
  std::optional<std::string> error() const override { return recorder_->error(); }
  std::optional<std::string> write_problem() const override { return recorder_->write_problem(); }
  bool waits_when_full() const override { return waits_; }
  std::vector<RecordingAlarm> take_alarms() override {
    std::lock_guard lock(alarm_mutex_);
    std::vector<RecordingAlarm> out;
    out.swap(alarms_);
    return out;
  }

  std::int64_t campaign() const { return campaign_; }
  storage::Recorder& recorder() { return *recorder_; }

 private:
  RunFiles& files_;
  std::int64_t campaign_;
  bool waits_;
  std::mutex alarm_mutex_;  // declared before the recorder, whose handler uses it until it is gone
  std::vector<RecordingAlarm> alarms_;
  std::unique_ptr<storage::Recorder> recorder_;
};

void RunFiles::set_hooks(Hooks hooks) {
  std::lock_guard lock(mutex_);
  hooks_ = std::move(hooks);
}

RecordingOpened RunFiles::open(const Request& request) {
  Hooks hooks;
  int attempt = 0;
  {
    std::lock_guard lock(mutex_);
    hooks = hooks_;
    if (opens_campaign_ != request.campaign) opens_ = 0;
    opens_campaign_ = request.campaign;
    attempt = opens_++;
  }
  storage::RunDb db = std::filesystem::exists(request.path) ? storage::RunDb::open(request.path)
                                                            : storage::RunDb::create(request.path, request.meta);
  RecordingOpened opened;
  opened.last_frame_t_ns = db.last_frame_t_ns();
  opened.last_temperature_t_ns = db.last_temperature_t_ns();
  opened.frames = db.frame_count();
  if (hooks.on_open) hooks.on_open(db, attempt);

  storage::RecorderOptions options;
  options.commit_interval_s = config_.recorder.commit_interval_s;
  options.queue_capacity_frames = config_.recorder.queue_frames;
  options.wait_when_full = hooks.wait_when_full.value_or(request.paced_by_consumer);
  auto recording = std::make_unique<StorageRecording>(*this, request.campaign, options.wait_when_full);
  recording->start(std::move(db), options, request.committed, hooks.after_commit);
  {
    std::lock_guard lock(mutex_);
    current_ = recording.get();
  }
  opened.recording = std::move(recording);
  return opened;
}

void RunFiles::forget(const StorageRecording* recording) {
  std::lock_guard lock(mutex_);
  if (current_ == recording) current_ = nullptr;
}

void RunFiles::write_record(std::int64_t campaign) {
  std::lock_guard lock(mutex_);
  if (current_ == nullptr || current_->campaign() != campaign) return;
  try {
    write_record_locked(campaign);
  } catch (const std::exception& e) {
    // The record is written again at the run's next event; the run goes on.
    spdlog::error("campaign {}: the run's record not written into its run file: {}", campaign, e.what());
  }
}

void RunFiles::write_record_locked(std::int64_t campaign) {
  json record = {{"campaign_id", campaign}, {"name", name_}, {"transitions", json::array()}, {"events", json::array()}};
  const std::vector<TransitionRow> transitions = db_.transitions(campaign);
  const std::vector<EventRow> events = db_.events(campaign);
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
  storage::Recorder& recorder = current_->recorder();
  const storage::RecorderStats rs = recorder.stats();
  record["recorder"] = {{"queue_capacity_frames", rs.queue_capacity_frames},
                        {"queue_high_water_frames", rs.high_water_frames},
                        {"dropped_frames", rs.dropped_frames}};
  // In the run file too, so that the run's own record tells every interruption; its faulted
  // intervals as the exported bundle's meta.json lists them.
  recorder.set_extra("imucald_run", record.dump());
  recorder.set_extra(storage::kFaultedIntervalsKey, faulted_intervals(transitions, events).dump());
}

void RunFiles::start(const RunStart& start) {
  std::lock_guard lock(mutex_);
  name_ = start.spec->name;
}

void RunFiles::event(const RunEvent& event) { write_record(event.campaign); }

// The run's last transition: written after it (the file refuses nothing more once it has failed).
void RunFiles::transition(const Transition& transition) {
  if (is_final(transition.to) || transition.to == RunState::Interrupted) write_record(transition.campaign);
}

// A recording that failed refuses these (the model stays in the service database).
void RunFiles::results(const RunResults& results) {
  if (results.failed) return;
  std::lock_guard lock(mutex_);
  if (current_ == nullptr || current_->campaign() != results.campaign) return;
  current_->recorder().set_extra("imucald_results", results.results.dump());
  if (results.model_json) current_->recorder().set_extra("imucald_model", *results.model_json);
}

void RunFiles::stop(const RunStop& stop) {
  std::lock_guard lock(mutex_);
  if (opens_campaign_ == stop.campaign) opens_ = 0;
}

}  // namespace imucal::daemon
