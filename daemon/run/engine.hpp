// The run engine: one campaign's run on the bench, segment by segment, with the run state machine
// of run_state.hpp, the suspenders (chamber out of band, IMU frames missing or corrupt, a device
// disconnected, a table fault: safe hold, automatic resume after the condition clears plus a settle
// time, the interrupted segment redone), operator commands (through RunControl) and the recording.
// It stores nothing and shows nothing itself: what happens leaves it as documents (documents.hpp)
// for the subscribers (the service database, alarms, the live feed, the run file's record, the
// online estimators). Its files include no storage header (checked by the suite).
//
// Checkpoints are the program's segment boundaries. Frames already recorded are never recorded
// again: a redone segment records only frames after the last one handed to the recording, so the
// run file holds every program instant exactly once whatever happened (pause, suspension, crash).
// Every path out of a run leaves the table at rate zero with its interlock open and the chamber at
// its safe set point.
#pragma once

#include <cstdint>
#include <string>

#include "daemon/config/config.hpp"
#include "daemon/devices/devices.hpp"
#include "daemon/run/documents.hpp"
#include "daemon/run/recording.hpp"
#include "daemon/run/run_control.hpp"

namespace imucal::daemon {

struct RunContext;
class PowerSwitch;
struct DeviceReadings;

class RunEngine {
 public:
  // `disk`: what a simulated bench's disk_full fault fills (the recording's storage).
  RunEngine(const DaemonConfig& config, RunControl& control, const Documents& documents, RecordingFactory& recordings,
            DiskFaultSwitch disk);

  // The campaign to run, as the service database holds it.
  struct Request {
    std::int64_t campaign = 0;
    std::string spec_json;
    std::int64_t lost_frames = 0, bad_frames = 0;  // counted so far (a resumed run counts on)
  };
  // From the campaign's checkpoint to the end of its program, or to the command or fault that ends
  // it; its last transition is made. Throws only what a subscriber throws at the very end.
  void run(const Request& request);

 private:
  enum class Outcome { Completed, Redo, Pause, Stop, Abort, Shutdown, Fail };

  bool open_run(RunContext& run);
  Outcome run_program(RunContext& run);
  void note_event(RunContext& run, const std::string& kind, const std::string& reason);
  void fail_early(std::int64_t id, const std::string& why);
  std::optional<Outcome> pending_command();

  void check_unit(RunContext& run);
  // Commits what the recording holds; false when it cannot (marks the run file failed when the
  // recording has stopped, not when it holds its frames for want of space).
  bool commit_recording(RunContext& run);
  void open_recording(RunContext& run);
  std::optional<std::string> recording_problem(RunContext& run);
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
  struct Ending;
  static Ending ending_of(Outcome outcome, double program_time_s, const std::string& reason);
  void finish_run(RunContext& run, Outcome outcome, const std::string& reason);
  void finish_estimators(RunContext& run, bool results);
  nlohmann::json telemetry_of(RunContext& run);
  void publish(RunContext& run, bool force);

  const DaemonConfig& config_;
  RunControl& control_;
  const Documents& documents_;
  RecordingFactory& recordings_;
  DiskFaultSwitch disk_;
};

}  // namespace imucal::daemon
