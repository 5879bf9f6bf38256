// One Modbus link (libmodbus, TCP or RTU) as the chamber driver and the power relay use it: its
// settings and their JSON keys, opening with a bounded connect and exponential backoff, and the
// typed error of a failed call. libmodbus stays in the .cpp; `Context` is its modbus_t.
// Not thread-safe: the owning driver serialises its calls.
#pragma once

#include <chrono>
#include <cstdint>
#include <string>

#include "drivers/interfaces.hpp"

struct _modbus;

namespace imucal {
class ObjectReader;  // core/json_reader.hpp
}

namespace imucal::drivers {

struct ModbusLinkConfig {
  enum class Transport { tcp, rtu } transport = Transport::tcp;
  std::string host = "127.0.0.1";  // tcp
  int port = 502;
  std::string serial_device = "/dev/ttyUSB0";  // rtu
  int baud = 9600;
  char parity = 'N';
  int data_bits = 8;
  int stop_bits = 1;
  std::chrono::milliseconds response_timeout{500};
  std::chrono::milliseconds backoff_initial{250};
  std::chrono::milliseconds backoff_max{8000};

  // "modbus-tcp://host:port" or "modbus-rtu://device@baud", for messages.
  std::string address() const;
};

// Reads the link keys of a device's JSON configuration ("transport", "host", "port",
// "serial_device", "baud", "parity", "data_bits", "stop_bits", "response_timeout_ms",
// "backoff_initial_ms", "backoff_max_ms"; absent keys keep `c`'s values) from a strict reader
// (core/json_reader.hpp) that throws at the first problem, naming the key.
void read_modbus_link(ObjectReader& r, ModbusLinkConfig& c);

class ModbusLink {
 public:
  using Context = _modbus;
  // `who` names the device in every message ("chamber modbus-tcp://...").
  ModbusLink(ModbusLinkConfig config, int slave_id, std::string who);
  ~ModbusLink();
  ModbusLink(const ModbusLink&) = delete;
  ModbusLink& operator=(const ModbusLink&) = delete;

  // The open context, opening the link if it is down; `force` ignores the backoff (an explicit
  // connect). Errors name the device and the cause.
  Result<Context*> open(bool force);
  bool is_open() const noexcept { return ctx_ != nullptr; }
  void close() noexcept;
  // The typed error of the libmodbus call that just failed (errno), "<who>: <what>: <cause>";
  // closes the link unless the device itself answered with an exception.
  DriverError fail(const std::string& what);
  const std::string& who() const noexcept { return who_; }
  std::uint64_t reconnects() const noexcept { return reconnects_; }

 private:
  ModbusLinkConfig cfg_;
  int slave_id_;
  std::string who_;
  Context* ctx_ = nullptr;
  std::chrono::steady_clock::time_point next_attempt_{};
  std::chrono::milliseconds backoff_;
  std::string last_error_;
  std::uint64_t reconnects_ = 0;
  bool ever_connected_ = false;
};

}  // namespace imucal::drivers
