// The devices of a calibration bench as the sequencer drives them: the three-axis table, the
// thermal chamber and the IMU under test. A small internal interface until drivers/interfaces.hpp
// (the drivers issue) lands; the in-process simulated bench implements it (sim_bench.hpp).
//
// One thread (the sequencer's) calls a Bench; implementations need no locking.
#pragma once

#include <cstdint>
#include <functional>
#include <optional>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "core/recording.hpp"

namespace imucal::daemon {

// The outcome of a device command: ok, or a message a person can act on.
struct DeviceResult {
  bool ok = true;
  std::string message;
  static DeviceResult success() { return {}; }
  static DeviceResult failure(std::string why) { return {false, std::move(why)}; }
};

struct TableState {
  Eigen::Vector3d angle_deg = Eigen::Vector3d::Zero();  // outer, middle, inner
  Eigen::Vector3d rate_dps = Eigen::Vector3d::Zero();
  bool homed = false;
  bool interlock_closed = false;
  bool moving = false;
  bool connected = true;
  std::string fault;  // empty: none
};

struct ChamberState {
  double temperature_C = 25.0;
  double setpoint_C = 25.0;
  bool connected = true;
};

struct ImuState {
  bool connected = true;
};

// What one read of the IMU gives: frames as delivered (the sequencer checks them) and the
// temperatures sampled meanwhile, both stamped in program time.
struct FrameBatch {
  std::vector<ImuFrame> frames;
  std::vector<TempSample> temps;
  void clear() {
    frames.clear();
    temps.clear();
  }
};

// The daemon's disk as a simulated `disk_full` fault (docs/api.md, sim_faults) reaches it: the
// process's full-disk switch of storage (storage::disk_fault), handed to the simulated benches by
// the sequencer, since the devices do not reach storage (docs/ARCHITECTURE.md). Empty: the fault
// does nothing.
struct DiskFaultSwitch {
  std::function<void(bool full)> set_full;
  std::function<std::int64_t()> refused_writes;  // writes refused so far (the fault is met)
  explicit operator bool() const { return set_full && refused_writes; }
};

class Table {
 public:
  virtual ~Table() = default;
  virtual DeviceResult home() = 0;
  virtual DeviceResult close_interlock() = 0;
  virtual DeviceResult open_interlock() = 0;
  // Rate zero on every axis, holding position (the safe hold and the first step of every exit).
  virtual DeviceResult stop() = 0;
  // Moves to the program's pose at program time t_s and follows the program from there (a
  // checkpoint: the start of a segment).
  virtual DeviceResult start_program_at(double t_s) = 0;
  virtual TableState state() const = 0;
};

class Chamber {
 public:
  virtual ~Chamber() = default;
  virtual DeviceResult set_setpoint(double setpoint_C) = 0;
  virtual ChamberState state() const = 0;
};

class Imu {
 public:
  virtual ~Imu() = default;
  // The frames with t_ns <= until_t_ns that have arrived (may be none), and the temperatures.
  virtual DeviceResult read(FrameBatch& out, std::int64_t until_t_ns) = 0;
  virtual ImuState state() const = 0;
  // What the run database records about the IMU and the set-up (rate, LSBs, site, segments).
  virtual RecordingMeta recording_meta() const = 0;
  // Whether the IMU's link carries its serial number (an identity message), and the serial it
  // reported, waiting up to wait_s of device time for it (empty: none arrived).
  virtual bool reports_serial() const { return false; }
  virtual std::optional<std::string> reported_serial(double wait_s) {
    (void)wait_s;
    return std::nullopt;
  }
};

// The IMU's supply, when the bench has a relay for it (drivers/power_relay.hpp): power-cycle
// segments then switch it themselves instead of asking the operator.
class PowerSwitch {
 public:
  virtual ~PowerSwitch() = default;
  virtual DeviceResult set_power(bool on) = 0;
  virtual double off_s() const = 0;  // how long a power cycle leaves the IMU unpowered
  virtual std::string describe() const = 0;
};

class Bench {
 public:
  virtual ~Bench() = default;
  virtual Table& table() = 0;
  virtual Chamber& chamber() = 0;
  virtual Imu& imu() = 0;
  // The IMU's power relay; nullptr when the operator switches the IMU.
  virtual PowerSwitch* power_switch() { return nullptr; }
  // The devices' clock in seconds (simulated time for simulated devices): timeouts and settle
  // times are measured on it, so that accelerated runs behave as real ones.
  virtual double now_s() const = 0;
  // Lets device time pass (a hold, a settle time). Returns early never; callers wait in steps.
  virtual void wait(double seconds) = 0;
  // True when frames are produced on demand (simulation): the recorder may then slow the
  // producer down instead of dropping frames.
  virtual bool paced_by_consumer() const = 0;
  // Program seconds per wall second when known (telemetry), 0 when as fast as possible.
  virtual double time_scale() const = 0;
  virtual std::string describe() const = 0;
  // A resumed run (after a restart): its first pass reached program time t_s (the last committed
  // frame) in an earlier process. Simulated benches only: a campaign's sim_faults at or before it
  // have fired already and are not injected again, and a simulated chamber that follows the
  // program's thermal model stands where it stood then (it starts there, not at the profile's start).
  virtual void resuming_after(double t_s) { (void)t_s; }
};

}  // namespace imucal::daemon
