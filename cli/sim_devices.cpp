// imucal sim-devices: the simulated table controller, chamber controller and IMU standalone on real
// addresses.
#include "cli/commands.hpp"

#include <signal.h>

#include <cstdio>
#include <string>

#include "core/imu_model.hpp"
#include "daemon/config/config.hpp"
#include "daemon/config/device_config.hpp"
#include "daemon/service.hpp"
#include "sim/sim_devices.hpp"

namespace imucal::cli {

// The simulated bench as separate devices on real addresses, for imucald's `devices` object (an
// operator's rehearsal, the tests of the configured-devices path). Runs until SIGINT/SIGTERM.
int run_sim_devices(const SimDevicesArgs& a) {
  // Taken by sigwait() below: blocked before the devices start their threads, which inherit it.
  const sigset_t signals = daemon::block_termination_signals();

  // The daemon's configuration, when given, says where the bench stands and what the table may
  // do: the simulated IMU must sense the same site the daemon calibrates for.
  const daemon::DaemonConfig config = a.config_file.empty() ? daemon::DaemonConfig{}
                                                            : daemon::load_config_file(a.config_file);
  sim::SimDevicesConfig c;
  for (std::size_t axis = 0; axis < 3; ++axis)
    c.servo.limits[axis].fill(daemon::table_limit_setting(config.table_limits.axis[axis]));
  c.table_port = a.table_port;
  c.table_dialect = a.table_dialect;
  c.chamber_port = a.chamber_port;
  c.chamber_start_C = config.chamber.safe_setpoint_C;
  c.chamber_tau_s = config.sim.chamber_tau_s;
  c.imu_socket_path = a.imu_socket;
  c.imu_link = a.imu_link;
  c.imu.framing = a.framing == "classic" ? drivers::can::Framing::classic : drivers::can::Framing::fd;
  c.imu.rate_hz = a.rate_hz;
  c.imu.seed = a.seed;
  c.imu.truth = a.truth == "ideal" ? ImuModel{} : read_imu_model_file(a.truth);
  c.imu.site = config.site;
  c.imu.temperature_C = config.chamber.safe_setpoint_C;
  c.imu_serial = a.serial.empty() ? "SIM-DEVICES-" + std::to_string(a.seed) : a.serial;
  if (c.imu.framing == drivers::can::Framing::classic && a.rate_hz > drivers::can::kClassicMaxRate_hz)
    throw std::invalid_argument("--framing classic carries at most 200 samples/s; --rate-hz is " + std::to_string(a.rate_hz));

  sim::SimDevices devices(c);
  if (devices.imu_serial_device().empty() && a.imu_socket.empty())
    throw std::invalid_argument("--imu-socket is required for a CAN IMU link ('" + a.imu_link + "')");
  const std::string imu_where = devices.imu_serial_device().empty()
                                    ? a.imu_socket + " (a new simulated IMU for each connection)"
                                    : "serial device " + devices.imu_serial_device() + " (a pseudo-terminal)";
  // stdout: the configuration to paste (a complete file on its own); stderr: what is going on.
  std::printf("{\"devices\": %s}\n", devices.devices_config_json().c_str());
  std::fflush(stdout);
  std::fprintf(stderr,
               "imucal sim-devices: table controller (dialect %s) on 127.0.0.1:%d, chamber controller (Modbus TCP, "
               "map %s) on 127.0.0.1:%d, IMU (%s) at %g Hz on %s; SIGINT or SIGTERM stops\n",
               a.table_dialect.c_str(), devices.table_port(), c.chamber_map.c_str(), devices.chamber_port(), a.imu_link.c_str(), a.rate_hz,
               imu_where.c_str());
  int signal_number = 0;
  sigwait(&signals, &signal_number);
  std::fprintf(stderr, "imucal sim-devices: %s, stopping after %llu IMU link(s)\n",
               signal_number == SIGTERM ? "SIGTERM" : "SIGINT", static_cast<unsigned long long>(devices.imu_links()));
  return 0;
}

}  // namespace imucal::cli
