// The bench of `--devices sim-wire`: the simulated table controller, chamber controller and IMU of
// drivers/sim, run in-process on their own threads and reached only through the real drivers of
// drivers/ -- the table over TCP (ACL, Boost.Asio), the chamber over Modbus TCP (libmodbus), the
// IMU over the SocketCAN driver on a socketpair(AF_UNIX, SOCK_SEQPACKET) -- all on 127.0.0.1 with
// ephemeral ports. It runs in real time (the simulated devices share one world clock, the host's).
//
// It adapts the drivers to the sequencer's Bench:
// - Table: the program is followed piece by piece with the controller's own primitives, so that
//   the simulated IMU senses exactly what the controller does: a hold is a position demand, a
//   cycloidal move a position demand (the controller moves rest to rest within the piece, with
//   its trapezoid at the table's limits), a rate piece a rate demand (a constant-acceleration ramp
//   is a rate demand with the rate-mode acceleration limit set to the ramp's). Sine pieces have no
//   controller primitive with the program's envelope: they are tracked in rate mode, the program's
//   rate plus a correction of the angle error, updated at every service step.
// - IMU: each sample's program time is the checkpoint's time plus whole sample periods counted by
//   the IMU's sequence numbers from the first sample after the table started following the program,
//   so frames lie on the program's frame grid and a lost sample is a gap the sequencer sees. The
//   table angles of a frame are the table driver's position reads interpolated (cubic Hermite,
//   angles and rates) at the sample's host time.
// - Chamber: set points written through Modbus; readings refreshed a few times a second.
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
#include "daemon/service/devices.hpp"
#include "drivers/interfaces.hpp"
#include "motion_programs/program.hpp"

namespace imucal::daemon {

struct WireBenchSettings {
  Site site;
  double rate_hz = 100.0;
  std::uint64_t seed = 1;
  ImuModel truth;
  motion::TableLimits limits;
  double chamber_tau_s = 20.0;
  double chamber_start_C = 25.0;
  double chamber_safe_setpoint_C = 25.0;
  double home_timeout_s = 120.0;  // homing and repositioning must end within this
};

class WireBench final : public Bench {
 public:
  // Starts the simulated devices and brings the three drivers up (connect, configure, activate
  // for the chamber and the IMU). Throws std::runtime_error naming the device that failed.
  // `program` must outlive the bench.
  WireBench(const motion::Program& program, const WireBenchSettings& settings);
  ~WireBench() override;

  Table& table() override;
  Chamber& chamber() override;
  Imu& imu() override;
  double now_s() const override;
  void wait(double seconds) override;
  bool paced_by_consumer() const override { return false; }  // real time: a device never waits
  double time_scale() const override { return 1.0; }
  std::string describe() const override;

 private:
  struct Devices;  // simulated devices and drivers (Asio, libmodbus stay in the .cpp)
  class TableFacade;
  class ChamberFacade;
  class ImuFacade;

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

  // One service step: polls the IMU (up to max_wait_ms), reads the table, refreshes the chamber
  // every quarter second, and issues the program's demands that are due.
  void service(int max_wait_ms);
  void read_table();
  void follow_program();
  bool demand_piece(std::size_t piece);
  void track_sines();
  DeviceResult reposition(const Eigen::Vector3d& target_deg);
  DeviceResult stop_motion();
  void restore_limits();
  std::optional<double> program_time_s(std::int64_t host_ns) const;
  std::int64_t anchor_ns() const;  // the checkpoint the program is followed from, in ns
  bool interpolate(std::int64_t host_ns, Eigen::Vector3d& angle_deg) const;

  const motion::Program& program_;
  WireBenchSettings settings_;
  std::int64_t dt_ns_;
  std::unique_ptr<Devices> dev_;
  std::unique_ptr<TableFacade> table_;
  std::unique_ptr<ChamberFacade> chamber_;
  std::unique_ptr<ImuFacade> imu_;

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
  std::string table_error_;                    // a refused demand while following: a table fault
  bool homed_ = false;
};

}  // namespace imucal::daemon
