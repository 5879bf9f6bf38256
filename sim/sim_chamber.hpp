// A simulated chamber controller: a real libmodbus TCP server on 127.0.0.1 (its own thread) that
// serves the registers of a RegisterMap, with first-order thermal dynamics of the air towards
// the working set point, an optional controller-side ramp, a units register, alarms, and fault
// injection (dropped connections, late replies, corrupted replies, silence, alarms).
#pragma once

#include <chrono>
#include <cstdint>
#include <memory>
#include <vector>

#include "drivers/interfaces.hpp"
#include "drivers/register_map.hpp"

namespace imucal::sim {

struct SimChamberConfig {
  drivers::RegisterMap map;
  double initial_C = 22.0;
  double ambient_C = 22.0;          // where the air goes with control off
  double time_constant_s = 60.0;    // first-order lag of the air to the working set point
  drivers::TemperatureUnit unit = drivers::TemperatureUnit::celsius;  // for maps with a units register
  int port = 0;                     // 0: any free port (see port())
  // Digital outputs served as coils 0.. (a controller's relay outputs; one may switch the IMU's
  // supply, drivers/power_relay.hpp). They start clear.
  int digital_outputs = 8;
  // World seconds per host second: the air (and a set point ramp) moves this much faster.
  double time_scale = 1.0;
};

// A write that changed a digital output, in seconds since the server started.
struct CoilChange {
  double t_s;
  int coil;
  bool set;
};

class SimChamber {
 public:
  // Binds and starts serving; throws std::runtime_error when the socket cannot be opened.
  explicit SimChamber(SimChamberConfig config);
  ~SimChamber();
  SimChamber(const SimChamber&) = delete;
  SimChamber& operator=(const SimChamber&) = delete;

  int port() const noexcept;

  // Truth, in Celsius.
  double process_C() const;
  double setpoint_C() const;
  double working_setpoint_C() const;
  bool control_on() const;
  std::uint64_t requests() const;  // requests answered or dropped
  bool coil(int address) const;
  std::vector<CoilChange> coil_changes() const;

  // What the front panel would change.
  void set_unit(drivers::TemperatureUnit unit);
  void set_coil(int address, bool set);  // not recorded as a change
  // The outputs forced by hand on the front panel: coil writes are acknowledged but not taken.
  void set_outputs_forced(bool forced);
  // Sets alarms[index] of the map to `raw` (an active value); clear_alarms() restores normal.
  void set_alarm(std::size_t index, std::uint16_t raw);
  void clear_alarms();

  // Faults.
  void drop_connections();                          // close every client connection now
  void set_reply_delay(std::chrono::milliseconds delay);  // each reply sent this late
  void corrupt_next_replies(int count);             // replies with a wrong transaction id
  void set_silent(bool silent);                     // read requests, never answer
  // A sensor fault: the process value served reads this much off the air temperature (the
  // control loop is not affected, so the reading stays off until the offset is removed).
  void set_reading_offset(double delta_C);

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace imucal::sim
