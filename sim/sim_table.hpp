// A simulated three-axis table controller: an Asio TCP server on 127.0.0.1 (its own thread)
// speaking any table dialect (drivers/table_dialect.hpp; imucal's ACL-style language by default:
// the driver's tests run against the dialect the driver is given), executing the commands on
// the world's TableServo, with its own clock (offset and drift) for the time tags of its
// replies, and fault injection (dropped connections, late, corrupted or missing replies, an
// emergency stop from the panel).
#pragma once

#include <chrono>
#include <cstdint>
#include <memory>
#include <string>

#include "sim/sim_world.hpp"
#include "drivers/table_dialect.hpp"

namespace imucal::sim {

struct SimTableConfig {
  int port = 0;  // 0: any free port (see port())
  double clock_drift_ppm = 0.0;   // the controller's clock against the world clock
  std::int64_t clock_offset_us = 0;
  std::string identity = "IMUCAL,SIM-TABLE,0,1.0";
  drivers::dialect::Dialect dialect = drivers::dialect::imucal_acl();
};

class SimTable {
 public:
  // Binds and starts serving; throws std::runtime_error when the port cannot be bound.
  SimTable(SimWorld& world, SimTableConfig config);
  ~SimTable();
  SimTable(const SimTable&) = delete;
  SimTable& operator=(const SimTable&) = delete;

  int port() const noexcept;
  // The controller's time tag for a world time.
  std::int64_t device_time_us(double world_s) const noexcept;
  std::uint64_t commands() const noexcept;

  // Faults.
  void drop_connections();                               // close every session now
  void set_reply_delay(std::chrono::milliseconds delay);  // each reply this late
  void corrupt_next_replies(int count);                  // flip one byte (never the terminator)
  void set_silent(bool silent);                          // read commands, never answer
  void trip_interlock();                                 // emergency stop from the panel

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace imucal::sim
