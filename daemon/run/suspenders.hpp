// The conditions that put a run in safe hold ("suspenders", after Bluesky's): each an object with
// what trips it, how serious it is, and when the run may go on, checked by the sequencer while it
// records and asked again before it moves (so the rule to hold and the rule to resume are one).
// Pure: readings in, a reason out; no device, no clock of its own. Listed by GET /api/suspenders.
#pragma once

#include <memory>
#include <optional>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "daemon/config/config.hpp"  // SuspenderSettings

namespace imucal::daemon {

// What the sequencer reads at one instant (device time).
struct DeviceReadings {
  double now_s = 0.0;
  bool table_connected = true;
  std::string table_fault;  // empty: none
  bool chamber_connected = true;
  double chamber_C = 0.0, setpoint_C = 0.0, tolerance_C = 0.0;
  bool imu_connected = true;
  double last_frame_s = 0.0;  // when the last IMU frame arrived (while recording)
  std::string frame_problem;  // bad or dropped frames in the last batch (empty: none)
  std::string recorder_problem;  // the recorder's most serious alarm (empty: none)
};

class Suspender {
 public:
  virtual ~Suspender() = default;
  virtual const char* name() const = 0;
  virtual std::string condition() const = 0;  // what trips it, with the configured numbers
  virtual const char* severity() const { return "suspend"; }
  virtual std::string resume_rule() const = 0;
  // While recording: why the run must hold now, or nothing.
  virtual std::optional<std::string> trip(const DeviceReadings& r) = 0;
  // Before the table moves (after a hold, or before a segment): whether it is clear.
  virtual bool clear(const DeviceReadings& r) const = 0;
  // A segment starts: persistence and timers count from now.
  virtual void reset() {}
};

struct Trip {
  std::string suspender;  // its name
  std::string reason;     // for the operator, with the readings
};

class Suspenders {
 public:
  explicit Suspenders(const SuspenderSettings& settings);
  // The first suspender that trips (in the order of the list).
  std::optional<Trip> trip(const DeviceReadings& r);
  // Whether every suspender is clear.
  bool clear(const DeviceReadings& r) const;
  void reset();
  // [{"name", "condition", "severity", "resume"}] (docs/api.md).
  nlohmann::json describe() const;

 private:
  std::vector<std::unique_ptr<Suspender>> list_;
};

}  // namespace imucal::daemon
