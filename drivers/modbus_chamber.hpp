// Chamber driver over Modbus TCP or RTU (libmodbus), for any controller whose registers a
// RegisterMap describes. Every call is bounded by the response timeout; a broken link is closed
// and reopened on a later call with exponential backoff; a ramp is run by the controller when the
// map has a ramp-rate register, else by this driver (stepping the set point on each read()).
// Thread-safe: calls are serialised by an internal mutex.
#pragma once

#include <chrono>
#include <memory>
#include <optional>
#include <string>

#include "drivers/interfaces.hpp"
#include "drivers/modbus_link.hpp"
#include "drivers/register_map.hpp"

namespace imucal::drivers {

// The link (drivers/modbus_link.hpp) and what the chamber adds to it.
struct ModbusChamberConfig : ModbusLinkConfig {
  RegisterMap map;
  // safe_stop(): go to this set point with control on; empty: switch control off (needs a
  // control-mode register).
  std::optional<double> safe_setpoint_C = 25.0;
  double setpoint_min_C = -70.0;  // set points outside are refused (invalid_argument)
  double setpoint_max_C = 180.0;
};

// "imucal-chamber/1" JSON: {"transport": "tcp"|"rtu", "host", "port", "serial_device", "baud",
// "parity", "data_bits", "stop_bits", "map": name|path|object, "response_timeout_ms",
// "backoff_initial_ms", "backoff_max_ms", "safe_setpoint_C" (number or null), "setpoint_range_C"}.
// Throws std::invalid_argument naming the key.
ModbusChamberConfig modbus_chamber_config_from_json(const std::string& json_text);

class ModbusChamber final : public Chamber {
 public:
  explicit ModbusChamber(ModbusChamberConfig config);
  ~ModbusChamber() override;
  ModbusChamber(const ModbusChamber&) = delete;
  ModbusChamber& operator=(const ModbusChamber&) = delete;

  Result<void> connect() override;
  Result<void> configure() override;
  Result<void> activate() override;
  Result<void> safe_stop() override;
  void disconnect() noexcept override;
  DeviceState state() const override;
  std::string describe() const override;

  Result<void> set_setpoint(double setpoint_C) override;
  Result<void> ramp_to(double target_C, double rate_C_per_min) override;
  Result<ChamberReading> read() override;
  Result<void> check_alarms() override;

  // Link statistics for the run record.
  std::uint64_t reconnects() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace imucal::drivers
