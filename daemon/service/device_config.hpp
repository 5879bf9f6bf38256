// Real devices named in the daemon's configuration (`devices` as an object, docs/daemon.md): the
// table controller and the chamber controller in the drivers' own configuration forms
// (imucal-table/1, imucal-chamber/1, parsed by the drivers' parsers), and the IMU under test on a
// CAN interface or on a Unix socket that carries the same CAN frame images. Only std and the
// drivers' plain configuration headers are included here (no Asio, no libmodbus).
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include <nlohmann/json_fwd.hpp>

#include "drivers/acl_table.hpp"
#include "drivers/can_protocol.hpp"
#include "drivers/modbus_chamber.hpp"
#include "motion_programs/program.hpp"

namespace imucal::daemon {

// The IMU under test: exactly one of `interface` and `socket_path` is set.
struct ImuDeviceConfig {
  std::string interface;    // a SocketCAN interface, opened as a CAN_RAW socket ("can0")
  std::string socket_path;  // a Unix SOCK_SEQPACKET socket carrying struct can(fd)_frame images
  drivers::can::Framing framing = drivers::can::Framing::fd;
  double rate_hz = 1000.0;     // the IMU's own sample rate: every campaign runs at it
  double gyro_lsb_rad = 0.0;   // one count of the gyro increments
  double accel_lsb_mps = 0.0;  // one count of the velocity increments
  std::string serial;          // recorded in every run's metadata
  std::int64_t transport_delay_ns = 0;  // fixed receive delay not covered by the latency field
  std::int64_t stall_timeout_ms = 500;  // no sample for this long: the stream stalled

  // "can0 (CAN FD)" or "socket /run/imucal/imu.sock (CAN FD frames)", for messages.
  std::string describe() const;
};

struct DeviceAddresses {
  drivers::AclTableConfig table;
  drivers::ModbusChamberConfig chamber;
  ImuDeviceConfig imu;
};

// One axis's program limits as the table controller takes them (its configure() and the
// simulated controller's servo).
drivers::AxisLimitSetting table_limit_setting(const motion::AxisLimits& limits);

// Reads the `devices` object at `where` ("config.devices"): unknown keys, missing required keys
// and every value the drivers' parsers refuse are listed in `problems`, each with its key path.
// The result is meaningful only when nothing was added to `problems`.
DeviceAddresses read_device_addresses(const nlohmann::json& devices, const std::string& where,
                                      std::vector<std::string>& problems);

}  // namespace imucal::daemon
