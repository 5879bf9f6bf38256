// The three simulated devices of a bench together, as `imucal sim-devices` runs them standalone and
// `imucald --devices sim-wire` runs them in-process: the table controller (its dialect over TCP)
// and the chamber controller (Modbus TCP) on 127.0.0.1 ports, and the IMU speaking its link description:
// on CAN, either a Unix SOCK_SEQPACKET socket listening on a path (each connection gets a new
// simulated IMU, the old one is dropped: the daemon opens the link once per run) or a link end
// handed over with attach_imu() (a socket pair); on a serial line, a pseudo-terminal whose slave
// device the daemon opens by its path (imu_serial_device()). Table and IMU share one SimWorld, so
// the IMU senses the motion the table controller makes.
#pragma once

#include <cstdint>
#include <functional>
#include <memory>
#include <string>

#include "sim/sim_chamber.hpp"
#include "sim/sim_imu.hpp"
#include "sim/sim_table.hpp"
#include "sim/sim_world.hpp"

namespace imucal::sim {

struct SimDevicesConfig {
  ServoConfig servo;                  // the table's limits per axis and mode
  int table_port = 0;                 // 0: any free port (see table_port())
  std::string table_dialect = "imucal-acl";  // the controller's language: built-in name or file
  int chamber_port = 0;
  std::string chamber_map = "watlow-f4t";  // a built-in register map or a map file
  double chamber_start_C = 25.0;      // initial air temperature, also the ambient
  double chamber_tau_s = 20.0;        // first-order time constant of the air
  std::string imu_socket_path;        // CAN: empty: no listener, links come through attach_imu()
  std::string imu_link = "imucal-can";  // the IMU's link description: built-in name or file
  SimImuConfig imu;                   // rate, seed, truth, site, framing (its link: imu_link)
  std::string imu_serial = "SIM-IMU"; // what the printed configuration names the IMU
  // World seconds per host second (sim_world.hpp): the table's motion, the IMU's samples and the
  // chamber's air run this much faster; the devices' clocks and the wire's timing do not.
  double time_scale = 1.0;
};

class SimDevices {
 public:
  // The chamber controller's digital output wired to the IMU's supply (normally open, set at the
  // start: the IMU is powered). The simulated IMU does not model its supply: switching it off
  // does not stop its stream; the power-on's new turn-on bias is the in-process simulator's.
  static constexpr int kImuPowerCoil = 0;

  // Starts the table and chamber servers and the IMU listener. Throws std::runtime_error naming
  // the device and the address that could not be opened (a port in use, a path that exists and
  // is not a socket).
  explicit SimDevices(SimDevicesConfig config);
  ~SimDevices();
  SimDevices(const SimDevices&) = delete;
  SimDevices& operator=(const SimDevices&) = delete;

  const SimDevicesConfig& config() const noexcept;
  int table_port() const noexcept;
  int chamber_port() const noexcept;
  // The per-unit LSBs of its increments (for a description that leaves them to the unit).
  double gyro_lsb_rad() const noexcept;
  double accel_lsb_mps() const noexcept;
  // A serial IMU: the pseudo-terminal device to open (empty for CAN).
  const std::string& imu_serial_device() const noexcept;

  // A new simulated IMU on this end of a link (it takes the descriptor); the previous one, if
  // any, stops and is dropped.
  void attach_imu(int socket_fd);
  std::uint64_t imu_links() const noexcept;  // links attached so far
  // f(imu) on the IMU of the current link under the devices' lock (fault injection); false when
  // there is none yet.
  bool with_imu(const std::function<void(SimImu&)>& f);

  SimWorld& world() noexcept;
  SimTable& table() noexcept;
  SimChamber& chamber() noexcept;

  // The `devices` object of imucald's configuration (docs/daemon.md) that reaches these devices,
  // as pretty JSON text. Needs the IMU socket path.
  std::string devices_config_json() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace imucal::sim
