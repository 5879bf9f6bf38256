// The driver interfaces the daemon programs against: a three-axis rate table, a thermal chamber
// and the IMU under test, each with the same lifecycle and the same typed errors. Real devices
// (ACL over TCP, Modbus, IMU links described as data over CAN, serial or UDP) and the simulated
// devices of sim/ sit behind these.
//
// Rules every implementation keeps:
// - No exception leaves a driver call (nor an Asio handler inside one): failures come back as
//   Result<T> holding a DriverError (an enum plus a message a person can act on). Constructors
//   may throw on invalid configuration, caught at the daemon's edge.
// - Every call is bounded in time (response timeouts; reconnection is attempted at most once per
//   call and never blocks longer than the connect timeout).
// - A value is returned only if it was read from the device by this call: no cached value is
//   ever reported as fresh. A failed read is an error, never the previous reading.
// - Times are int64 nanoseconds on one host time base, host_time_ns() (CLOCK_REALTIME, the clock
//   of the kernel's SO_TIMESTAMP receive stamps). Each driver maps its device's clock onto it with
//   a fitted clock model, so that table angles and IMU samples can be put side by side.
//
// This header must stay light: no Asio, no libmodbus, no socket headers.
#pragma once

#include <array>
#include <chrono>
#include <cstdint>
#include <optional>
#include <stdexcept>
#include <string>
#include <utility>
#include <variant>
#include <vector>

#include "core/recording.hpp"

namespace imucal::drivers {

// ------------------------------------------------------------------------------------------------
// Errors

enum class DriverErrc {
  not_connected = 1,   // call needs a connection; none is open (reconnection is backing off)
  connect_failed,      // could not open the connection / device (message names it and why)
  timeout,             // no (complete) reply within the response timeout
  connection_lost,     // peer closed or reset the connection mid-call
  protocol_error,      // malformed or unexpected reply, wrong length, implausible value
  crc_error,           // checksum of a reply or frame does not match
  device_rejected,     // the device answered with an error reply (message carries its text)
  interlock_open,      // the table refuses motion: interlock open
  limit_exceeded,      // a demand outside the configured limits (position, rate, acceleration)
  axis_fault,          // an axis hit a limit or faulted and needs an interlock reset
  watchdog_expired,    // the table's track watchdog dropped an axis to off
  alarm,               // the chamber reports an active alarm
  invalid_argument,    // caller error: bad axis, NaN demand, ...
  invalid_state,       // lifecycle call out of order (e.g. demand before connect)
  stream_stalled,      // the IMU stream delivered nothing within its stall timeout
  io_error,            // an operating-system call failed (message carries errno text)
  unsupported,         // the device or its register map has no such function
};

const char* to_string(DriverErrc code) noexcept;

struct DriverError {
  DriverErrc code = DriverErrc::io_error;
  std::string message;
};

// Value or error. Small on purpose: the daemon checks `if (!r)` and reads r.error().message.
template <class T>
class [[nodiscard]] Result {
 public:
  Result(T value) : v_(std::move(value)) {}  // NOLINT: implicit on purpose (return value;)
  Result(DriverError error) : v_(std::move(error)) {}  // NOLINT
  Result(DriverErrc code, std::string message) : v_(DriverError{code, std::move(message)}) {}

  bool ok() const noexcept { return v_.index() == 0; }
  explicit operator bool() const noexcept { return ok(); }
  // Precondition ok() / !ok(); checked by std::get (throws std::bad_variant_access otherwise,
  // which is a programming error, not a device failure).
  T& value() & { return std::get<0>(v_); }
  const T& value() const& { return std::get<0>(v_); }
  T&& value() && { return std::get<0>(std::move(v_)); }
  T& operator*() & { return value(); }
  const T& operator*() const& { return value(); }
  T* operator->() { return &value(); }
  const T* operator->() const { return &value(); }
  const DriverError& error() const { return std::get<1>(v_); }
  DriverErrc code() const { return ok() ? DriverErrc{} : error().code; }

 private:
  std::variant<T, DriverError> v_;
};

template <>
class [[nodiscard]] Result<void> {
 public:
  Result() = default;
  Result(DriverError error) : e_(std::move(error)) {}  // NOLINT
  Result(DriverErrc code, std::string message) : e_(DriverError{code, std::move(message)}) {}

  bool ok() const noexcept { return !e_.has_value(); }
  explicit operator bool() const noexcept { return ok(); }
  // Precondition !ok(), checked as Result<T>'s: std::logic_error otherwise (a programming error).
  const DriverError& error() const {
    if (!e_) throw std::logic_error("Result<void>::error() on a success");
    return *e_;
  }
  DriverErrc code() const { return e_ ? e_->code : DriverErrc{}; }

 private:
  std::optional<DriverError> e_;
};

inline Result<void> success() { return {}; }

// The one host time base: CLOCK_REALTIME in ns (std::chrono::system_clock on Linux), the clock
// of SO_TIMESTAMP. Only drivers read it; estimators get times with the samples.
inline std::int64_t host_time_ns() {
  return std::chrono::duration_cast<std::chrono::nanoseconds>(
             std::chrono::system_clock::now().time_since_epoch())
      .count();
}

// ------------------------------------------------------------------------------------------------
// Lifecycle, common to every device:
//   disconnected --connect--> connected --configure--> configured --activate--> active
//   safe_stop: from any state, bring the hardware to its safe state (table at rest with the
//   interlock open, chamber at its safe set point or off, IMU stream stopped); ends in
//   `configured` when the link is up. disconnect: release the link (after safe_stop).
// A connection lost while active puts the device in `faulted`; the next call tries to reconnect
// (with backoff) where that is safe, and reports the loss as an error in any case.
enum class DeviceState { disconnected, connected, configured, active, faulted };
const char* to_string(DeviceState state) noexcept;

class Device {
 public:
  virtual ~Device() = default;
  virtual Result<void> connect() = 0;
  virtual Result<void> configure() = 0;
  virtual Result<void> activate() = 0;
  virtual Result<void> safe_stop() = 0;
  virtual void disconnect() noexcept = 0;
  virtual DeviceState state() const = 0;
  // One line naming the device and its address, for logs and error messages.
  virtual std::string describe() const = 0;
};

// ------------------------------------------------------------------------------------------------
// Three-axis table. Axis index 0 = outer, 1 = middle, 2 = inner (motion::kAxisNames); angles are
// the encoder angles of CONVENTIONS.md in degrees.

inline constexpr int kTableAxes = 3;

enum class TableMode { off, position, rate, synthesis };
const char* to_string(TableMode mode) noexcept;

// Limits per axis and per mode: angle range, rate and acceleration. Infinite range = slip rings.
struct AxisLimitSetting {
  double min_deg = -1e9;
  double max_deg = 1e9;
  double rate_dps = 300.0;
  double accel_dps2 = 300.0;
};

// Synthesis mode: angle = centre + amplitude * sin(2 pi f (t - t_ref) + phase), where t_ref is
// the table's synthesis epoch (common to all axes, so phases between axes are meaningful) and the
// centre is the axis position when the oscillation is demanded.
struct OscillationDemand {
  double amplitude_deg = 0.0;
  double frequency_hz = 0.0;
  double phase_deg = 0.0;
};

// Three angles sampled by the table controller at one servo instant.
struct TablePositions {
  std::int64_t t_ns = 0;           // that instant on the host time base (clock model)
  std::int64_t device_time_us = 0; // the controller's own time tag
  std::array<double, 3> angle_deg{};
  std::array<double, 3> rate_dps{};
  std::int64_t round_trip_ns = 0;  // request to reply; bounds the mapping error of this one read
};

enum class InterlockState { open, closed };

struct AxisStatus {
  TableMode mode = TableMode::off;
  bool at_limit = false;          // reached a position limit (latched until interlock reset)
  bool fault = false;             // any latched fault on this axis
  bool watchdog_expired = false;  // dropped to off by the track watchdog (latched)
  bool moving = false;            // |rate| above the table's at-rest threshold
};

struct TableStatus {
  std::int64_t t_ns = 0;  // host time of the reply
  InterlockState interlock = InterlockState::open;
  std::array<AxisStatus, 3> axes{};
};

class Table : public Device {
 public:
  virtual Result<void> interlock_close() = 0;
  virtual Result<void> interlock_open() = 0;
  // Clears latched faults (limit hit, watchdog); axes stay off.
  virtual Result<void> interlock_reset() = 0;
  virtual Result<void> set_mode(int axis, TableMode mode) = 0;
  virtual Result<void> demand_position(int axis, double angle_deg) = 0;
  virtual Result<void> demand_rate(int axis, double rate_dps) = 0;
  virtual Result<void> demand_oscillation(int axis, const OscillationDemand& demand) = 0;
  virtual Result<void> set_limits(int axis, TableMode mode, const AxisLimitSetting& limits) = 0;
  // Track watchdog: while armed (period > 0), an axis not off that receives no demand for
  // `period_s` is dropped to off. 0 disarms. Demands (or a repeated demand) feed it.
  virtual Result<void> set_watchdog(double period_s) = 0;
  virtual Result<TablePositions> read_positions() = 0;
  virtual Result<TableStatus> read_status() = 0;
};

// ------------------------------------------------------------------------------------------------
// Thermal chamber. The API is in degrees Celsius whatever unit the controller works in.

enum class TemperatureUnit { celsius, fahrenheit };

struct ChamberAlarm {
  std::string name;        // from the register map
  std::uint16_t raw = 0;   // the register value that made it active
};

struct ChamberReading {
  std::int64_t t_ns = 0;  // host time of the read
  double process_C = 0.0;
  double setpoint_C = 0.0;                     // the set point register as read back
  std::optional<double> working_setpoint_C;    // the controller's ramping set point, if mapped
  std::optional<double> ramp_target_C;         // a ramp in progress (driver- or device-side)
  TemperatureUnit device_unit = TemperatureUnit::celsius;
  std::vector<ChamberAlarm> alarms;            // active alarms; empty when none
};

class Chamber : public Device {
 public:
  virtual Result<void> set_setpoint(double setpoint_C) = 0;
  // Ramp the set point linearly at rate_C_per_min. Uses the controller's ramp register when the
  // map has one; otherwise the driver steps the set point on each read() (call read() at least
  // about once a second while ramping).
  virtual Result<void> ramp_to(double target_C, double rate_C_per_min) = 0;
  // Process value, set points, unit and alarms, all read by this call. Active alarms come back in
  // the reading (the values are still valid); check_alarms() turns them into an error.
  virtual Result<ChamberReading> read() = 0;
  // Error DriverErrc::alarm naming every active alarm; success when none.
  virtual Result<void> check_alarms() = 0;
};

// ------------------------------------------------------------------------------------------------
// IMU under test.

// One sample as the IMU delivered it, decoded by its link description (imu_link.hpp): the
// increments over (t_prev, t] in SI, whatever the IMU sends (scaled integers or floats, increments
// or rates).
struct ImuSample {
  std::uint32_t sequence = 0;       // running count of samples (the IMU's counter, unwrapped)
  std::int64_t t_ns = 0;            // sample instant on the host time base (clock model)
  std::int64_t device_time_ns = 0;  // the IMU's own time tag (or its sample count x period)
  std::int64_t rx_ns = 0;           // receive time of the frame (kernel stamp where there is one)
  std::uint32_t latency_us = 0;     // sample instant to transmission, as the IMU reports it
  std::array<double, 3> dtheta_rad{};
  std::array<double, 3> dv_mps{};
  std::uint64_t status = 0;  // raw status bits (the description says which mean invalid data)
  bool status_fault = false; // a fault bit is set: the data are delivered but suspect
  double gyro_temp_C = 0.0;  // block temperatures carried in the sample frame (NaN: none)
  double accel_temp_C = 0.0;

  // Increments in rad and m/s, table angles left zero (the daemon fills them from the table).
  ImuFrame to_frame() const;
};

// The slower temperature message: every FOG coil sensor (8 per gyro) and each accelerometer.
struct ImuTemperatures {
  std::int64_t t_ns = 0;
  std::int64_t device_time_ns = 0;
  std::array<double, 24> coil_C{};  // gyro x sensors 0..7, y 0..7, z 0..7
  std::array<double, 3> accel_C{};

  TempSample to_temp_sample() const;  // coil means per gyro; chamber fields left default
};

// Counters since activate(): what went wrong on the wire, per run.
struct ImuCounters {
  std::uint64_t frames_received = 0;     // frames of the description decoded or refused
  std::uint64_t samples_delivered = 0;
  std::uint64_t temperature_messages = 0;
  std::uint64_t sequence_gaps = 0;       // events where the sequence jumped
  std::uint64_t samples_lost = 0;        // samples missing in those jumps
  std::uint64_t crc_failures = 0;        // checksum mismatches (CRC, sum, XOR)
  std::uint64_t malformed_frames = 0;    // wrong length or header, non-finite value, stale
                                         // sequence, incomplete classic set or temperature set
  std::uint64_t resyncs = 0;             // byte streams: runs of garbage skipped to a header
  std::uint64_t bytes_discarded = 0;     // byte streams: bytes that belonged to no good frame
  std::uint64_t status_faults = 0;       // samples delivered with a fault status bit
  std::uint64_t stalls = 0;              // stream_stalled errors returned
};

// The clock model mapping device time to the host time base: host = offset + (1 + drift) * dev.
struct ClockModelState {
  bool valid = false;
  double drift_ppm = 0.0;
  double residual_rms_ns = 0.0;  // scatter of receive times about the fitted lower envelope
  std::size_t points = 0;
  std::uint64_t resets = 0;  // restarts of the fit on a clock jump since the device was made
};

struct ImuBatch {
  std::vector<ImuSample> samples;
  std::vector<ImuTemperatures> temperatures;
};

class Imu : public Device {
 public:
  // activate() starts the stream. poll() waits up to max_wait for data and appends what arrived
  // to `out` (samples in sequence order). It returns an error, without data, for a stalled stream
  // (nothing within the configured stall timeout) or a lost link; CRC failures, gaps and status
  // faults are counted (counters()) and are not errors: good samples keep flowing.
  virtual Result<void> poll(ImuBatch& out, std::chrono::milliseconds max_wait) = 0;
  virtual ImuCounters counters() const = 0;
  virtual ClockModelState clock_model() const = 0;
  // The serial number the IMU reported over its link (an identity message), once it has; never
  // for an IMU whose link carries none.
  virtual std::optional<std::string> reported_serial() const { return std::nullopt; }
};

}  // namespace imucal::drivers
