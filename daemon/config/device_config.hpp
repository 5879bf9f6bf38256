// Real devices named in the daemon's configuration (`devices` as an object, docs/daemon.md): the
// table controller and the chamber controller in the drivers' own configuration forms
// (imucal-table/1, imucal-chamber/1, parsed by the drivers' parsers), and the IMU under test: its
// link description (imucal-imu-link/1, by name, path or inline) and where the link is: a CAN
// interface or a Unix socket carrying the same CAN frame images, a serial device, or a UDP port.
// Only std and the drivers' plain configuration headers are included here (no Asio, no libmodbus).
#pragma once

#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include <nlohmann/json_fwd.hpp>

#include "drivers/can_protocol.hpp"
#include "drivers/imu_link.hpp"
#include "drivers/modbus_chamber.hpp"
#include "drivers/power_relay.hpp"
#include "drivers/tcp_table.hpp"
#include "motion_programs/program.hpp"

namespace imucal::daemon {

// The IMU under test: its link description and the address its transport needs (socketcan:
// exactly one of `interface` and `socket_path`; serial: `serial_device`; udp: `udp_port`).
struct ImuDeviceConfig {
  std::string link_name = "imucal-can";  // as configured: a built-in name, a path, or "inline"
  drivers::link::ImuLink link;           // per-unit LSBs resolved from gyro_lsb_rad/accel_lsb_mps
  std::string interface;      // socketcan: a SocketCAN interface, opened as a CAN_RAW socket ("can0")
  std::string socket_path;    // socketcan: a Unix SOCK_SEQPACKET socket carrying struct can(fd)_frame images
  drivers::can::Framing framing = drivers::can::Framing::fd;
  std::string serial_device;  // serial: the device ("/dev/ttyUSB0"), line settings from the link
  std::string udp_bind = "0.0.0.0";  // udp: where the datagrams arrive
  int udp_port = 0;
  std::string udp_peer_host;  // udp: the IMU's address (commands go there, only its data is taken)
  int udp_peer_port = 0;
  double rate_hz = 1000.0;     // the IMU's own sample rate: every campaign runs at it
  std::string serial;          // recorded in every run's metadata
  std::int64_t transport_delay_ns = 0;  // fixed receive delay not covered by the latency field
  std::int64_t stall_timeout_ms = 500;  // no sample for this long: the stream stalled

  // "can0 (CAN FD, imucal-can)", "serial /dev/ttyUSB0 (kvh-1750)", for messages.
  std::string describe() const;
};

// The register map of the simulated chamber controller that `sim-wire` reaches.
inline constexpr const char* kSimWireChamberMap = "watlow-f4t";

struct DeviceAddresses {
  drivers::TcpTableConfig table;
  drivers::ModbusChamberConfig chamber;
  ImuDeviceConfig imu;
  // The relay that switches the IMU's supply (imucal-power-relay/1); none: the operator does.
  std::optional<drivers::PowerRelayConfig> power_relay;
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
