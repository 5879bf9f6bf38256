#include "drivers/modbus_link.hpp"

#include <algorithm>
#include <cerrno>
#include <stdexcept>

#include <modbus/modbus.h>

#include "core/json_reader.hpp"

namespace imucal::drivers {

using Clock = std::chrono::steady_clock;

std::string ModbusLinkConfig::address() const {
  if (transport == Transport::tcp) return "modbus-tcp://" + host + ":" + std::to_string(port);
  return "modbus-rtu://" + serial_device + "@" + std::to_string(baud);
}

void read_modbus_link(ObjectReader& r, ModbusLinkConfig& c) {
  if (const auto t = r.string("transport")) {
    if (*t == "tcp") c.transport = ModbusLinkConfig::Transport::tcp;
    else if (*t == "rtu") c.transport = ModbusLinkConfig::Transport::rtu;
    else r.fail(r.at("transport") + " must be \"tcp\" or \"rtu\", not \"" + *t + "\"");
  }
  if (const auto v = r.string("host")) c.host = *v;
  if (const auto v = r.integer("port", 1, 65535)) c.port = static_cast<int>(*v);
  if (const auto v = r.string("serial_device")) c.serial_device = *v;
  if (const auto v = r.integer("baud", 1, 4'000'000)) c.baud = static_cast<int>(*v);
  if (const auto p = r.string("parity")) {
    if (*p != "N" && *p != "E" && *p != "O") r.fail(r.at("parity") + " must be \"N\", \"E\" or \"O\"");
    c.parity = (*p)[0];
  }
  if (const auto v = r.integer("data_bits", 5, 8)) c.data_bits = static_cast<int>(*v);
  if (const auto v = r.integer("stop_bits", 1, 2)) c.stop_bits = static_cast<int>(*v);
  read_milliseconds(r, "response_timeout_ms", c.response_timeout);
  read_milliseconds(r, "backoff_initial_ms", c.backoff_initial);
  read_milliseconds(r, "backoff_max_ms", c.backoff_max);
}

ModbusLink::ModbusLink(ModbusLinkConfig config, int slave_id, std::string who)
    : cfg_(std::move(config)), slave_id_(slave_id), who_(std::move(who)), backoff_(cfg_.backoff_initial) {}

ModbusLink::~ModbusLink() { close(); }

void ModbusLink::close() noexcept {
  if (ctx_) {
    modbus_close(ctx_);
    modbus_free(ctx_);
    ctx_ = nullptr;
  }
}

Result<ModbusLink::Context*> ModbusLink::open(bool force) {
  if (ctx_) return ctx_;
  const auto now = Clock::now();
  if (!force && now < next_attempt_) {
    const auto wait = std::chrono::duration_cast<std::chrono::milliseconds>(next_attempt_ - now);
    return DriverError{DriverErrc::not_connected,
                       who_ + ": link down (" + last_error_ + "), next attempt in " + std::to_string(wait.count()) + " ms"};
  }
  modbus_t* c = nullptr;
  if (cfg_.transport == ModbusLinkConfig::Transport::tcp)
    c = modbus_new_tcp(cfg_.host.c_str(), cfg_.port);
  else
    c = modbus_new_rtu(cfg_.serial_device.c_str(), cfg_.baud, cfg_.parity, cfg_.data_bits, cfg_.stop_bits);
  if (!c) return DriverError{DriverErrc::connect_failed, who_ + ": cannot create the Modbus context: " + modbus_strerror(errno)};
  const auto to_us = std::chrono::duration_cast<std::chrono::microseconds>(cfg_.response_timeout).count();
  modbus_set_response_timeout(c, static_cast<std::uint32_t>(to_us / 1000000), static_cast<std::uint32_t>(to_us % 1000000));
  // Between bytes of one reply: a real controller streams a reply without pauses.
  modbus_set_byte_timeout(c, 0, static_cast<std::uint32_t>(std::min<long long>(to_us, 500000)));
  modbus_set_slave(c, slave_id_);
  // libmodbus uses the response timeout for the TCP connect as well, so this is bounded.
  if (modbus_connect(c) == -1) {
    const std::string why = modbus_strerror(errno);
    modbus_free(c);
    last_error_ = "connect failed: " + why;
    next_attempt_ = now + backoff_;
    backoff_ = std::min(backoff_ * 2, cfg_.backoff_max);
    return DriverError{DriverErrc::connect_failed, who_ + ": " + last_error_};
  }
  ctx_ = c;
  backoff_ = cfg_.backoff_initial;
  if (ever_connected_) ++reconnects_;
  ever_connected_ = true;
  return ctx_;
}

DriverError ModbusLink::fail(const std::string& what) {
  const int e = errno;
  const std::string text = who_ + ": " + what + ": " + modbus_strerror(e);
  DriverErrc code = DriverErrc::io_error;
  bool link_ok = false;
  switch (e) {
    case EMBXILFUN: case EMBXILADD: case EMBXILVAL: case EMBXSFAIL: case EMBXACK:
    case EMBXSBUSY: case EMBXNACK: case EMBXMEMPAR: case EMBXGPATH: case EMBXGTAR:
      code = DriverErrc::device_rejected;
      link_ok = true;
      break;
    case ETIMEDOUT: code = DriverErrc::timeout; break;
    case EMBBADCRC: code = DriverErrc::crc_error; break;
    case EMBBADDATA: case EMBBADEXC: case EMBUNKEXC: case EMBMDATA: case EMBBADSLAVE:
      code = DriverErrc::protocol_error;
      break;
    case ECONNRESET: case EPIPE: case ECONNREFUSED: case ENOTCONN: case EBADF: case ECONNABORTED:
      code = DriverErrc::connection_lost;
      break;
    default: break;
  }
  if (!link_ok) {
    // After a timeout or a garbled reply the stream position is unknown and a late reply could
    // be taken for the answer to the next request: start over on a fresh connection. The
    // first reconnection is tried at once, later ones back off.
    close();
    last_error_ = what + ": " + modbus_strerror(e);
    next_attempt_ = Clock::now();
  }
  return {code, text};
}

}  // namespace imucal::drivers
