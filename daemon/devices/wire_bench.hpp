// The bench of the real drivers of drivers/: the table over TCP (ACL, Boost.Asio), the chamber over
// Modbus (libmodbus), the IMU through the SocketCAN driver. It serves two device sets the same way:
// - real devices at the addresses of imucald's `devices` object (DeviceAddresses), the IMU on a
//   CAN interface or on a Unix SOCK_SEQPACKET socket carrying the same frame images;
// - `--devices sim-wire`: the simulated table controller, chamber controller and IMU of
//   drivers/sim (sim::SimDevices), started in-process and owned by the bench, on 127.0.0.1 with
//   ephemeral ports and the IMU on a socket pair.
// It runs in real time, on the host time base; sim-wire may run accelerated (SimWireSettings::
// time_scale): the simulated physics run k program seconds per host second, the wire and the
// drivers' timeouts in host time.
//
// It adapts the drivers to the sequencer's Bench:
// - Table: the program is followed piece by piece with the controller's own primitives, so that
//   the IMU senses exactly what the controller does: a hold is a position demand, a cycloidal
//   move a position demand (the controller moves rest to rest within the piece, with its
//   trapezoid at the table's limits), a rate piece a rate demand (a constant-acceleration ramp
//   is a rate demand with the rate-mode acceleration limit set to the ramp's). Sine pieces have no
//   controller primitive with the program's envelope: they are tracked in rate mode, the program's
//   rate plus a correction of the angle error, updated at every service step. With the table's
//   watchdog armed, the last demand of every axis under control is repeated as its keep-alive.
// - IMU: each sample's program time is the checkpoint's time plus whole sample periods counted by
//   the IMU's sequence numbers from the first sample after the table started following the program,
//   so frames lie on the program's frame grid and a lost sample is a gap the sequencer sees. The
//   table angles of a frame are the table driver's position reads interpolated (cubic Hermite,
//   angles and rates) at the sample's host time.
// - Chamber: set points written through Modbus; readings refreshed a few times a second, the
//   first one before the bench is handed over.
// - Power: the IMU's supply relay (a Modbus coil) when configured; sim-wire uses the simulated
//   chamber's digital output 0.
//
// Like every Bench it is called from the sequencer's thread only.
#pragma once

#include <array>
#include <cstdint>
#include <deque>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "core/imu_model.hpp"
#include "daemon/campaign/campaign.hpp"
#include "daemon/config/device_config.hpp"
#include "daemon/devices/devices.hpp"
#include "drivers/interfaces.hpp"
#include "motion_programs/program.hpp"

namespace imucal::sim {
class SimDevices;
}

namespace imucal::daemon {

struct WireBenchSettings {
  Site site;
  double rate_hz = 100.0;  // the campaign's frame rate: must be the IMU's
  motion::TableLimits limits;  // the program's limits; the table controller gets them where the
                               // device configuration names none
  double home_timeout_s = 120.0;  // homing and repositioning must end within this
  // The real table's certificate, recorded in the run's meta (the simulated devices of sim-wire
  // are an ideal table: none).
  std::optional<table::TableCertificate> table;
};

// sim-wire: what the simulated devices started by the bench simulate.
struct SimWireSettings {
  std::uint64_t seed = 1;
  ImuModel truth;
  double chamber_tau_s = 20.0;
  double chamber_start_C = 25.0;
  double chamber_safe_setpoint_C = 25.0;
  // A campaign's sim_faults, injected on the simulated devices themselves when the program first
  // reaches them (docs/daemon.md): the daemon sees them only through the drivers.
  std::vector<SimFault> faults;
  DiskFaultSwitch disk;  // what a disk_full fault fills
  // The serial the simulated IMU reports over its link: the campaign's unit when it names one
  // (the simulated IMU is that unit), else SIM-WIRE-<seed>.
  std::string imu_serial;
  // Program seconds per host second (imucald's sim.wire_time_scale): the simulated table's
  // motion, the IMU's samples and the chamber's air run this much faster, on the same wire and
  // drivers, whose timeouts stay in host time (a fault must outlast them in host time to show).
  double time_scale = 1.0;
};

class WireBench final : public Bench {
 public:
  // Real devices at the configured addresses. Opens the IMU link first (it touches nothing), then
  // brings the table (connect, configure), the chamber (connect, configure, activate, first read)
  // and the IMU (connect, configure, activate) up. Throws std::runtime_error naming the device,
  // its address and the reason; devices already brought up are parked first (table axes off and
  // interlock open, chamber at its safe set point) and the message says so. `program` must
  // outlive the bench.
  WireBench(const motion::Program& program, const WireBenchSettings& settings, const DeviceAddresses& devices);
  // sim-wire: starts the simulated devices in-process and reaches them the same way.
  WireBench(const motion::Program& program, const WireBenchSettings& settings, const SimWireSettings& simulated);
  ~WireBench() override;

  Table& table() override;
  Chamber& chamber() override;
  Imu& imu() override;
  PowerSwitch* power_switch() override;  // when devices.power_relay names one (sim-wire: always)
  double now_s() const override;  // host time base, from the bench's start
  void wait(double seconds) override;
  bool paced_by_consumer() const override { return false; }  // real time: a device never waits
  double time_scale() const override { return time_scale_; }
  std::string describe() const override;
  void resuming_after(double t_s) override;

  // sim-wire: the simulated devices; nullptr with real devices.
  sim::SimDevices* simulated_devices() { return sim_.get(); }

 private:
  struct Devices;  // the drivers (Asio, libmodbus stay in the .cpp)
  class TableFacade;
  class ChamberFacade;
  class ImuFacade;
  class PowerFacade;

  struct TableRead {
    std::int64_t t_ns = 0;  // host time base
    std::array<double, 3> angle_deg{};
    std::array<double, 3> rate_dps{};
  };
  struct PendingSample {
    std::int64_t host_t_ns = 0;
    std::int64_t program_t_ns = 0;
    ImuFrame frame;  // increments; angles filled when a table read after it exists
  };
  // A campaign's sim_fault on the simulated devices (sim-wire).
  struct InjectedFault {
    SimFault fault;
    bool fired = false;         // once, on the first pass (a redo does not fire it again)
    std::int64_t until_ns = 0;  // host time its effect is taken back
    bool over = false;
  };
  // The last demand sent to an axis, repeated as the watchdog's keep-alive.
  struct AxisDemand {
    drivers::TableMode mode = drivers::TableMode::off;
    double value = 0.0;  // deg (position) or deg/s (rate)
    std::int64_t sent_ns = 0;
  };

  // Brings the drivers up on addresses_ (the IMU link already open when imu_fd >= 0).
  void start(int imu_fd);
  void open_imu(int imu_fd);   // start's first step: the IMU link opened and connected
  // start's: the relay a power-cycling program needs, powering the IMU.
  void check_power_relay(const drivers::PowerRelayConfig& relay);
  void park_after_failed_start(std::string& message);
  // One service step: polls the IMU (up to max_wait_ms), reads the table, refreshes the chamber
  // every quarter second, and issues the program's demands that are due.
  void service(int max_wait_ms);
  void read_table();
  void follow_program();
  bool demand_piece(std::size_t piece);
  void track_sines();
  drivers::Result<void> demand(int axis, drivers::TableMode mode, double value);
  void keep_alive();
  void fire_faults(std::int64_t program_t_ns);
  void expire_faults();
  DeviceResult reposition(const Eigen::Vector3d& target_deg);
  DeviceResult stop_motion();
  void restore_limits();
  std::optional<double> program_time_s(std::int64_t host_ns) const;
  std::int64_t anchor_ns() const;  // the checkpoint the program is followed from, in ns
  bool interpolate(std::int64_t host_ns, Eigen::Vector3d& angle_deg) const;
  // Program (device) nanoseconds in a span of host nanoseconds, and back.
  std::int64_t device_ns(std::int64_t host_span_ns) const;
  std::int64_t host_ns(double device_s) const;

  const motion::Program& program_;
  WireBenchSettings settings_;
  DeviceAddresses addresses_;
  std::string truth_json_;        // sim-wire: the simulated IMU's truth; real devices: none
  std::string imu_link_;          // where the IMU's frames come from, for describe()
  std::int64_t dt_ns_;
  double time_scale_ = 1.0;       // program (device) seconds per host second; 1 with real devices
  std::int64_t epoch_ns_;         // host time of the bench's start (now_s() counts from it)
  std::int64_t keep_alive_ns_ = 0;  // demand repeat period; 0: the table's watchdog is off
  // Declared before the drivers: the drivers close their links before the devices stop.
  std::unique_ptr<sim::SimDevices> sim_;
  std::unique_ptr<Devices> dev_;
  std::unique_ptr<TableFacade> table_;
  std::unique_ptr<ChamberFacade> chamber_;
  std::unique_ptr<ImuFacade> imu_;
  std::unique_ptr<PowerFacade> power_;

  // Device state as last read (the sequencer polls state() often; the wire is read in service()).
  TableState table_state_;
  ChamberState chamber_state_;
  std::int64_t next_chamber_read_ns_ = 0;
  std::deque<TableRead> reads_;
  std::string imu_error_;  // the last poll error, until the next good poll

  // Following the program: anchored at host time anchor_ns_ = program time anchor_t_s_.
  bool following_ = false;
  std::int64_t anchor_host_ns_ = 0;
  double anchor_t_s_ = 0.0;
  std::size_t next_piece_ = 0;      // the next piece whose demands are due
  std::optional<std::uint32_t> first_sequence_;
  std::int64_t first_program_t_ns_ = 0;
  std::int64_t delivered_t_ns_ = 0;  // program time of the last frame handed to the sequencer
  std::deque<PendingSample> pending_;
  std::vector<TempSample> pending_temps_;
  std::array<bool, 3> rate_limit_changed_{};
  std::array<drivers::TableMode, 3> modes_{};  // as last read or set
  std::array<AxisDemand, 3> demands_{};
  std::vector<InjectedFault> faults_;  // sim-wire only
  DiskFaultSwitch disk_;                // sim-wire only
  std::string table_error_;                    // a refused demand while following: a table fault
  bool homed_ = false;
};

}  // namespace imucal::daemon
