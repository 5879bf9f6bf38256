#include "daemon/run/engine.hpp"

#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <limits>
#include <thread>

#include <spdlog/spdlog.h>

#include "core/number_text.hpp"
#include "core/units.hpp"
#include "daemon/campaign/campaign.hpp"
#include "daemon/devices/bench_factory.hpp"
#include "daemon/run/suspenders.hpp"

namespace imucal::daemon {

using nlohmann::json;
using Clock = std::chrono::steady_clock;
namespace fs = std::filesystem;

namespace {

double seconds(Clock::duration d) { return std::chrono::duration<double>(d).count(); }

json vec3(const Eigen::Vector3d& v) { return json::array({v.x(), v.y(), v.z()}); }

}  // namespace

// Everything about the run in progress; lives on the sequencer thread only.
struct RunContext {
  std::int64_t id = 0;
  CampaignSpec spec;
  motion::Program program;
  std::vector<SegmentInfo> segments;
  std::unique_ptr<Bench> bench;
  bool estimators_finishing = false;  // the program has ended; the estimators work through its tail
  std::unique_ptr<RunRecording> recorder;
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

RunEngine::RunEngine(const DaemonConfig& config, RunControl& control, const Documents& documents,
                     RecordingFactory& recordings, DiskFaultSwitch disk)
    : config_(config), control_(control), documents_(documents), recordings_(recordings), disk_(std::move(disk)) {}

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
void RunEngine::check_unit(RunContext& run) {
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
// write), takes up from what it holds, and starts recording into it.
void RunEngine::open_recording(RunContext& run) {
  RecordingFactory::Request request;
  request.campaign = run.id;
  request.path = run.run_db_path;
  request.meta = recording_meta(run);
  request.paced_by_consumer = run.bench->paced_by_consumer();
  request.committed = [this, id = run.id](std::int64_t t_ns) {
    documents_.emit(&RunSubscriber::frames_committed, FramesCommitted{id, t_ns});
  };
  RecordingOpened opened = recordings_.open(request);
  // Where the file leaves off: the resume point after a restart.
  run.last_t_ns = opened.last_frame_t_ns;
  run.last_temp_t_ns = opened.last_temperature_t_ns;
  run.frames = opened.frames;
  run.recorder = std::move(opened.recording);
  run.recorder_waits = run.recorder->waits_when_full();
  run.recorder_failed = false;
}

// The recording's alarms since the last call, each an alarm event of the run. Returns why the run
// must suspend: the writer falls behind a device that cannot wait, dropped frames, or failed.
std::optional<std::string> RunEngine::recording_problem(RunContext& run) {
  if (!run.recorder) return std::nullopt;
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
  using Kind = RecordingAlarm::Kind;
  for (const RecordingAlarm& alarm : run.recorder->take_alarms()) {
    // A producer that waits for room loses nothing: a high queue is then the intended pacing.
    if (alarm.kind == Kind::QueueHighWater && run.recorder_waits) continue;
    char counts[160];
    std::snprintf(counts, sizeof counts, " (queue high-water mark %lld of %lld frames, %lld frames dropped)",
                  static_cast<long long>(alarm.stats.high_water_frames),
                  static_cast<long long>(alarm.stats.queue_capacity_frames),
                  static_cast<long long>(alarm.stats.dropped_frames));
    note_event(run, "alarm", "recorder " + alarm.kind_name + ": " + alarm.message + counts);
    switch (alarm.kind) {
      case Kind::QueueHighWater: raise_reason(1, "the recorder falls behind: its queue passed its high-water level"); break;
      case Kind::FramesDropped: raise_reason(2, "the recorder fell behind and dropped frames"); break;
      // The recording holds what it could not write and tries again; the run waits for it.
      case Kind::WriteHeld: raise_reason(3, alarm.message); break;
      case Kind::WriteFailed:
        run.recorder_failed = true;
        raise_reason(4, "recording failed: " + alarm.message);
        break;
    }
  }
  return reason;
}

bool RunEngine::commit_recording(RunContext& run) {
  if (run.recorder->commit_and_wait()) return true;
  if (run.recorder->error()) run.recorder_failed = true;  // reopened before the run goes on
  return false;
}

void RunEngine::note_event(RunContext& run, const std::string& kind, const std::string& reason) {
  if (kind == "alarm" || kind == "error") {
    spdlog::warn("campaign {}: {}: {}", run.id, kind, reason);
  } else {
    spdlog::info("campaign {}: {}: {}", run.id, kind, reason);
  }
  documents_.emit(&RunSubscriber::event,
                  RunEvent{run.id, kind, static_cast<std::int64_t>(run.segment), run.program_time_s, reason});
}

// A run that fails before its bench exists: nothing moved, nothing recorded.
void RunEngine::fail_early(std::int64_t id, const std::string& why) {
  documents_.emit(&RunSubscriber::error, RunError{id, why});
  documents_.emit(&RunSubscriber::event, RunEvent{id, "error", std::nullopt, std::nullopt, why});
  control_.transition(RunState::Failed, why, std::nullopt);
}

std::optional<RunEngine::Outcome> RunEngine::pending_command() {
  const auto request = control_.pending();
  if (!request) return std::nullopt;
  switch (*request) {
    case RunControl::Request::Pause: return Outcome::Pause;
    case RunControl::Request::Stop: return Outcome::Stop;
    case RunControl::Request::Abort: return Outcome::Abort;
    case RunControl::Request::Shutdown: return Outcome::Shutdown;
  }
  return std::nullopt;
}

// The run file (created on the first start, reopened to resume) and its recording; the RunStart
// document (the estimators' subscriber tails the file from here). Returns whether the run resumes
// an earlier one.
bool RunEngine::open_run(RunContext& run) {
  const std::string relative = "runs/" + std::to_string(run.id) + ".db";
  run.run_db_path = (fs::path(config_.data_dir) / relative).string();
  fs::create_directories(fs::path(run.run_db_path).parent_path());
  const bool resuming = fs::exists(run.run_db_path);
  open_recording(run);
  const auto committed_t = run.last_t_ns;
  // A resumed run's faults up to what is committed fired in the process that recorded it.
  if (committed_t) run.bench->resuming_after(static_cast<double>(*committed_t) / units::kNsPerS);
  documents_.emit(&RunSubscriber::start, RunStart{run.id, &run.spec, run.run_db_path, relative, resuming, committed_t});
  return resuming;
}

// The program from the run's checkpoint to its end (or to the command or fault that ends it):
// segment after segment, pausing, holding and redoing as the state machine says.
RunEngine::Outcome RunEngine::run_program(RunContext& run) {
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
    documents_.emit(&RunSubscriber::checkpoint,
                    Checkpoint{run.id, static_cast<std::int64_t>(run.segment), run.checkpoint_s()});
    if (run.segments[run.segment].kind == "power-cycle" && run.power_cycled_segment != run.segment) {
      outcome = await_power_cycle(run);
      if (outcome != Outcome::Completed) continue;
    }
    outcome = run_segment(run);
    if (outcome == Outcome::Completed) ++run.segment;
  }
  return outcome;
}

void RunEngine::run(const Request& request) {
  RunContext run;
  run.id = request.campaign;
  // A resumed run counts on from what it had counted (lost and bad frames as last stored; the
  // frames from the run file): before issue 33 a restart set both back to zero.
  run.lost = request.lost_frames;
  run.bad = request.bad_frames;
  {
    const CampaignCheck check = check_campaign_text(request.spec_json, config_);
    if (!check.spec) {
      std::string why = "the campaign is no longer valid with this configuration:";
      for (const auto& p : check.problems) why += " " + p + ";";
      fail_early(run.id, why);
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

    run.bench = make_bench(config_, run.spec, run.program, disk_);
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
    spdlog::error("campaign {}: {}", run.id, why);
    if (run.bench) {
      documents_.emit(&RunSubscriber::error, RunError{run.id, why});
      note_event(run, "error", why);
      finish_run(run, Outcome::Fail, why);
    } else {
      fail_early(run.id, why);
    }
  }
}

RunEngine::Outcome RunEngine::prepare_devices(RunContext& run) {
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
DeviceReadings RunEngine::readings(RunContext& run, double setpoint_C, double tolerance_C) {
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

RunEngine::Outcome RunEngine::wait_until_ready(RunContext& run, bool suspended) {
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

// The pieces of RunEngine::run_segment's loop, one step each (small functions also keep
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
std::string record_frames(RunRecording& recorder, const std::vector<ImuFrame>& accepted, std::int64_t& frames,
                          std::int64_t& lost, std::optional<std::int64_t>& last_t_ns) {
  frames += static_cast<std::int64_t>(accepted.size());
  const auto pushed = recorder.push(accepted);
  if (pushed == RunRecording::Push::Rejected)
    throw std::runtime_error("internal error: the recorder refused frames that do not follow the recorded ones");
  if (pushed == RunRecording::Push::Refused) {
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
  if (pushed == RunRecording::Push::Dropped) {
    // Counted in the run file too (recorder_session, dropped_span); those instants stay a gap.
    lost += static_cast<std::int64_t>(accepted.size());
    return "the recorder fell behind and dropped frames";
  }
  return {};
}

}  // namespace

RunEngine::Outcome RunEngine::run_segment(RunContext& run) {
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
    if (auto why = recording_problem(run)) {
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
RunEngine::Outcome RunEngine::hold(RunContext& run, const std::string& reason) {
  publish(run, true);  // the counters as they are when the condition is found
  if (!control_.transition(RunState::Suspended, reason, RunState::Running)) {
    // An operator command arrived meanwhile; it takes precedence.
    if (auto r = run.bench->table().stop(); !r.ok) note_event(run, "alarm", "stopping the table: " + r.message);
    if (auto c = pending_command()) return *c;
    return Outcome::Redo;
  }
  note_event(run, "suspended", reason);
  safe_hold(run);
  (void)commit_recording(run);
  (void)recording_problem(run);  // alarms raised meanwhile become events
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
      (void)recording_problem(run);
      open_recording(run);
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
    (void)recording_problem(run);
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
  if (!control_.transition(RunState::Running, reason + " cleared", RunState::Suspended)) {
    if (auto c = pending_command()) return *c;
  }
  note_event(run, "resumed", text);
  return Outcome::Redo;
}

// Operator pause: table stopped, recorder committed, then wait for resume, stop or abort.
RunEngine::Outcome RunEngine::paused(RunContext& run) {
  safe_hold(run);
  if (run.recorder) (void)commit_recording(run);  // a failed file is reopened on resume
  // The counters first: whoever sees "paused" must see where the run holds.
  publish(run, true);
  if (!control_.transition(RunState::Paused, "table stopped, recording committed", RunState::Pausing)) {
    if (auto c = pending_command()) return *c;
  }
  note_event(run, "paused", "paused in segment " + std::to_string(run.segment) + " '" +
                                run.segments[run.segment].name + "'");
  publish(run, true);
  for (;;) {
    if (control_.state() == RunState::Paused) control_.wait(std::chrono::milliseconds(100));
    if (auto c = pending_command()) return *c;
    if (control_.state() == RunState::Running) break;
    publish(run, false);
  }
  const Outcome waited = wait_until_ready(run, false);
  if (waited != Outcome::Completed) return waited;
  note_event(run, "resumed", "redoing segment " + std::to_string(run.segment) + " '" + run.segments[run.segment].name +
                                 "' from " + number_text(run.checkpoint_s()) + " s");
  return Outcome::Redo;
}

RunEngine::Outcome RunEngine::await_power_cycle(RunContext& run) {
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
  control_.ask(run.segment, text);
  note_event(run, "prompt", text);
  publish(run, true);
  std::string who;
  for (;;) {
    if (auto answered = control_.take_answer()) {
      who = *answered;
      break;
    }
    if (auto c = pending_command()) {
      control_.withdraw_prompt();  // asked again when the run comes back to this segment
      return *c;
    }
    control_.wait(std::chrono::milliseconds(100));
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
std::optional<RunEngine::Outcome> RunEngine::switch_power(RunContext& run, PowerSwitch& power, std::string& failure) {
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

// Safe hold (pause, suspension): rate zero, then the interlock open, as on every path out of
// running; the next segment closes it again before the table moves.
void RunEngine::safe_hold(RunContext& run) {
  if (auto r = run.bench->table().stop(); !r.ok) note_event(run, "alarm", "stopping the table: " + r.message);
  if (auto r = run.bench->table().open_interlock(); !r.ok) note_event(run, "alarm", "opening the interlock: " + r.message);
}

void RunEngine::safe_exit(RunContext& run) {
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
// The estimators' final results once the program has ended (or cancelled): they may lag behind it
// (a fast time scale), so the run goes on publishing, its telemetry saying so, while their
// subscriber works through the tail.
void RunEngine::finish_estimators(RunContext& run, bool results) {
  run.estimators_finishing = results;
  try {
    documents_.emit(&RunSubscriber::ending, RunEnding{run.id, results, run.last_t_ns, [&] { publish(run, false); }});
  } catch (...) {
    run.estimators_finishing = false;
    throw;
  }
  run.estimators_finishing = false;
}

struct RunEngine::Ending {
  RunState state = RunState::Failed;
  std::string why;
  bool results = false;  // the estimators give results from the data so far
};

// Where an outcome leaves the run.
RunEngine::Ending RunEngine::ending_of(Outcome outcome, double program_time_s, const std::string& reason) {
  switch (outcome) {
    case Outcome::Completed: return {RunState::Done, "program complete", true};
    case Outcome::Stop:
      return {RunState::Done, "stopped early at " + number_text(program_time_s) + " s; results from the data so far",
              true};
    // The table is parked first (safe_exit); the estimators then finish on the data so far, as for
    // a stop: a partial run keeps its model (complete: false, counts only when an operator accepts it).
    case Outcome::Abort:
      return {RunState::Aborted,
              "aborted at " + number_text(program_time_s) + " s; table parked, results from the data so far", true};
    case Outcome::Shutdown:
      return {RunState::Interrupted,
              "the daemon shut down; table parked, recording committed; resume continues from the last checkpoint",
              false};
    default:  // what was recorded before the failure still calibrates (partial)
      return {RunState::Failed, reason.empty() ? "failed" : reason, true};
  }
}

void RunEngine::finish_run(RunContext& run, Outcome outcome, const std::string& reason) {
  try {
    safe_exit(run);
  } catch (const std::exception& e) {
    spdlog::error("campaign {}: safe exit: {}", run.id, e.what());
  }
  // The parked table in the telemetry before the run is seen final: a client that reads both
  // after the final state must not see the bench as it was before the safe exit.
  publish(run, true);
  Ending end = ending_of(outcome, run.program_time_s, reason);
  // A shutdown while the recording holds frames for want of space leaves the run interrupted:
  // those frames are lost with the process, and the resume takes up after the last commit.
  if (run.recorder && !run.recorder->commit_and_wait() && end.state != RunState::Failed &&
      !(end.state == RunState::Interrupted && !run.recorder->error())) {
    end.state = RunState::Failed;
    end.why = "recording failed: " +
              run.recorder->error().value_or(run.recorder->write_problem().value_or("unknown error"));
    documents_.emit(&RunSubscriber::error, RunError{run.id, end.why});
    // Its alarm; the run record is written again below (the recording refuses nothing more now).
    note_event(run, "error", end.why);
  }
  finish_estimators(run, end.results && is_final(end.state));
  RunStop stop{run.id, {run.program_time_s, run.frames, run.lost, run.bad}, std::nullopt};
  if (is_final(end.state)) stop.complete = outcome == Outcome::Completed && end.state == RunState::Done;
  documents_.emit(&RunSubscriber::stop, stop);
  control_.transition(end.state, end.why, std::nullopt);
  publish(run, true);
  if (run.recorder) (void)run.recorder->close();  // a failure was reported above
  run.recorder.reset();
}

// The live telemetry's body (docs/api.md "Live"; the live feed adds the estimators' progress).
json RunEngine::telemetry_of(RunContext& run) {
  const TableState ts = run.bench->table().state();
  const ChamberState cs = run.bench->chamber().state();
  const RecordingStats rs = run.recorder ? run.recorder->stats() : RecordingStats{};
  const RunState state = control_.state();
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
  t["run"]["prompt"] = control_.prompt();
  t["run"]["estimators_finishing"] = run.estimators_finishing;
  return t;
}

// The run as it looks now (at most 20 a second): the Snapshot document.
void RunEngine::publish(RunContext& run, bool force) {
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
  Snapshot snapshot{run.id, telemetry_of(run), {run.program_time_s, run.frames, run.lost, run.bad}, force};
  documents_.emit(&RunSubscriber::snapshot, snapshot);
}

}  // namespace imucal::daemon
