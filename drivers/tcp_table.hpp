// Table driver: a controller's command language described as data (table_dialect.hpp; imucal's
// ACL-style language by default) over TCP with Boost.Asio. Each call sends one command and waits
// for its one reply within the response timeout, running the driver's private io_context in the calling thread; no exception leaves a handler or a call.
// A timeout, a lost connection or a garbled reply closes the connection (a late reply can then
// never be taken for the answer to a later command); the next call reconnects, at once the first
// time and with exponential backoff after failures. Position reads are stamped on the host time
// base through a clock model fitted to (table time tag, request/reply midpoint) pairs.
// Thread-safe: calls are serialised by an internal mutex.
#pragma once

#include <array>
#include <chrono>
#include <memory>
#include <optional>
#include <string>

#include "drivers/clock_model.hpp"
#include "drivers/interfaces.hpp"
#include "drivers/table_dialect.hpp"

namespace imucal::drivers {

struct TcpTableConfig {
  std::string host = "127.0.0.1";
  int port = 5000;
  // The controller's language: a built-in dialect or a dialect file, as configured, and parsed.
  std::string dialect_name = "imucal-acl";
  dialect::Dialect dialect = dialect::imucal_acl();
  std::chrono::milliseconds response_timeout{500};
  std::chrono::milliseconds connect_timeout{1000};
  std::chrono::milliseconds backoff_initial{250};
  std::chrono::milliseconds backoff_max{8000};
  // Ask the table for reply checksums (the dialect's reply_checksum "on" command after each
  // connect); ignored for a dialect without them. From JSON: by default when the dialect has them.
  bool reply_checksum = true;
  // configure() sends these limits ([axis][mode], mode indexed by TableMode) and arms the
  // watchdog with this period (0: leave it off).
  std::array<std::array<std::optional<AxisLimitSetting>, 4>, 3> limits{};
  double watchdog_s = 0.0;
  // safe_stop() waits this long for every axis to be at rest before opening the interlock.
  std::chrono::milliseconds safe_stop_timeout{30000};
  // Named fields, as in LinkImuConfig (a positional list shifted when a field was added).
  ClockFitConfig clock{.block_span_ns = 500'000'000, .window_blocks = 64, .lower_envelope = false};
};

// "imucal-table/1" JSON: {"host", "port", "dialect" (a built-in name or a dialect file),
// "response_timeout_ms", "connect_timeout_ms",
// "backoff_initial_ms", "backoff_max_ms", "reply_checksum", "watchdog_s", "safe_stop_timeout_ms",
// "limits": [{"axis": "outer"|"middle"|"inner", "mode": "position"|"rate"|"synthesis"|"off",
// "min_deg", "max_deg", "rate_dps", "accel_dps2"}, ...]}. Throws std::invalid_argument.
TcpTableConfig tcp_table_config_from_json(const std::string& json_text);

class TcpTable final : public Table {
 public:
  explicit TcpTable(TcpTableConfig config);
  ~TcpTable() override;
  TcpTable(const TcpTable&) = delete;
  TcpTable& operator=(const TcpTable&) = delete;

  Result<void> connect() override;
  Result<void> configure() override;
  Result<void> activate() override;
  Result<void> safe_stop() override;
  void disconnect() noexcept override;
  DeviceState state() const override;
  std::string describe() const override;

  Result<void> interlock_close() override;
  Result<void> interlock_open() override;
  Result<void> interlock_reset() override;
  Result<void> set_mode(int axis, TableMode mode) override;
  Result<void> demand_position(int axis, double angle_deg) override;
  Result<void> demand_rate(int axis, double rate_dps) override;
  Result<void> demand_oscillation(int axis, const OscillationDemand& demand) override;
  Result<void> set_limits(int axis, TableMode mode, const AxisLimitSetting& limits) override;
  Result<void> set_watchdog(double period_s) override;
  Result<TablePositions> read_positions() override;
  Result<TableStatus> read_status() override;

  ClockModelState clock_model() const;
  std::uint64_t reconnects() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace imucal::drivers
