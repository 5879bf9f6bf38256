#include "drivers/tcp_table.hpp"

#include <cmath>
#include <mutex>
#include <thread>

#include <boost/asio/connect.hpp>
#include <boost/asio/io_context.hpp>
#include <boost/asio/ip/tcp.hpp>
#include <boost/asio/read_until.hpp>
#include <boost/asio/write.hpp>
#include <nlohmann/json.hpp>

#include "core/json_reader.hpp"


namespace imucal::drivers {

namespace asio = boost::asio;
using asio::ip::tcp;
using boost::system::error_code;
using Clock = std::chrono::steady_clock;

TcpTableConfig tcp_table_config_from_json(const std::string& json_text) {
  using nlohmann::json;
  json j;
  try {
    j = json::parse(json_text);
  } catch (const json::exception& e) {
    throw std::invalid_argument(std::string("table config: not valid JSON: ") + e.what());
  }
  TcpTableConfig c;
  ObjectReader r(j, "", ObjectReader::ThrowAtFirst{"table config: "});
  if (const auto f = r.string("format"); f && *f != "imucal-table/1") r.fail(r.at("format") + " must be \"imucal-table/1\"");
  if (const auto v = r.string("host")) c.host = *v;
  if (const auto v = r.integer("port", 1, 65535)) c.port = static_cast<int>(*v);
  read_milliseconds(r, "response_timeout_ms", c.response_timeout);
  read_milliseconds(r, "connect_timeout_ms", c.connect_timeout);
  read_milliseconds(r, "backoff_initial_ms", c.backoff_initial);
  read_milliseconds(r, "backoff_max_ms", c.backoff_max);
  read_milliseconds(r, "safe_stop_timeout_ms", c.safe_stop_timeout);
  if (const auto d = r.string("dialect")) {
    c.dialect_name = *d;
    c.dialect = dialect::load_dialect(c.dialect_name);
  }
  c.reply_checksum = r.boolean("reply_checksum").value_or(c.dialect.has_reply_checksum);
  if (c.reply_checksum && !c.dialect.has_reply_checksum)
    r.fail(r.at("reply_checksum") + " is true but dialect '" + c.dialect.name + "' has no reply checksum");
  if (const auto v = r.number_in("watchdog_s", 0.0)) c.watchdog_s = *v;
  if (const json* limits = r.get("limits")) {
    if (!limits->is_array()) r.fail(r.at("limits") + " must be an array, not " + json_type_name(*limits));
    for (std::size_t i = 0; i < limits->size(); ++i) {
      ObjectReader l((*limits)[i], "limits[" + std::to_string(i) + "]", ObjectReader::ThrowAtFirst{"table config: "});
      const std::string axis = l.required_string("axis");
      const std::string mode = l.required_string("mode");
      const int a = axis == "outer" ? 0 : axis == "middle" ? 1 : axis == "inner" ? 2 : -1;
      const int m = mode == "off" ? 0 : mode == "position" ? 1 : mode == "rate" ? 2 : mode == "synthesis" ? 3 : -1;
      if (a < 0) l.fail(l.at("axis") + " must be outer, middle or inner, not \"" + axis + "\"");
      if (m < 0) l.fail(l.at("mode") + " must be off, position, rate or synthesis, not \"" + mode + "\"");
      AxisLimitSetting s;
      s.min_deg = l.number("min_deg").value_or(s.min_deg);
      s.max_deg = l.number("max_deg").value_or(s.max_deg);
      s.rate_dps = l.number("rate_dps").value_or(s.rate_dps);
      s.accel_dps2 = l.number("accel_dps2").value_or(s.accel_dps2);
      if (!(s.min_deg < s.max_deg) || !(s.rate_dps > 0) || !(s.accel_dps2 > 0))
        l.fail(l.where() + " (" + axis + "/" + mode + ") needs min_deg < max_deg and positive rate_dps and accel_dps2");
      l.finish();
      c.limits[static_cast<std::size_t>(a)][static_cast<std::size_t>(m)] = s;
    }
  }
  r.finish();
  return c;
}

struct TcpTable::Impl {
  TcpTableConfig cfg;
  mutable std::mutex mutex;
  asio::io_context io;
  tcp::socket socket{io};
  std::string rx;
  bool checksum_on = false;
  DeviceState state = DeviceState::disconnected;
  Clock::time_point next_attempt{};
  std::chrono::milliseconds backoff;
  std::string last_link_error;
  std::uint64_t reconnects = 0;
  bool ever_connected = false;
  ClockFit clock;

  explicit Impl(TcpTableConfig c) : cfg(std::move(c)), backoff(cfg.backoff_initial), clock(cfg.clock) {}

  std::string who() const { return "table " + cfg.dialect.name + "://" + cfg.host + ":" + std::to_string(cfg.port); }
  const dialect::Dialect& lang() const { return cfg.dialect; }

  void close_link(const std::string& why) {
    if (socket.is_open()) {
      error_code ignored;
      socket.shutdown(tcp::socket::shutdown_both, ignored);
      socket.close(ignored);
      // Let the cancelled handlers run (they only record operation_aborted).
      io.restart();
      io.run();
    }
    rx.clear();
    checksum_on = false;
    last_link_error = why;
  }

  // Runs the io_context until `done` or the timeout; true when done.
  bool run_until(const bool& done, std::chrono::milliseconds timeout) {
    io.restart();
    const auto until = Clock::now() + timeout;
    while (!done) {
      const auto left = until - Clock::now();
      if (left <= Clock::duration::zero()) break;
      if (io.run_one_for(left) == 0 && io.stopped()) break;  // no work left: nothing can set `done`
    }
    return done;
  }

  Result<void> open_link(bool force) {
    if (socket.is_open()) return success();
    const auto now = Clock::now();
    if (!force && now < next_attempt) {
      const auto wait = std::chrono::duration_cast<std::chrono::milliseconds>(next_attempt - now);
      return {DriverErrc::not_connected,
              who() + ": link down (" + last_link_error + "), next attempt in " + std::to_string(wait.count()) + " ms"};
    }
    auto fail = [&](const std::string& why) -> Result<void> {
      close_link(why);
      next_attempt = Clock::now() + backoff;
      backoff = std::min(backoff * 2, cfg.backoff_max);
      return {DriverErrc::connect_failed, who() + ": " + why};
    };
    error_code ec;
    tcp::endpoint ep;
    const auto addr = asio::ip::make_address(cfg.host, ec);
    if (!ec) {
      ep = tcp::endpoint(addr, static_cast<unsigned short>(cfg.port));
    } else {
      tcp::resolver resolver(io);
      const auto results = resolver.resolve(cfg.host, std::to_string(cfg.port), ec);
      if (ec || results.empty()) return fail("cannot resolve host: " + ec.message());
      ep = *results.begin();
    }
    bool done = false;
    error_code connect_ec;
    socket.async_connect(ep, [&](const error_code& e) {
      connect_ec = e;
      done = true;
    });
    if (!run_until(done, cfg.connect_timeout)) return fail("connect timed out after " + std::to_string(cfg.connect_timeout.count()) + " ms");
    if (connect_ec) return fail("connect failed: " + connect_ec.message());
    socket.set_option(tcp::no_delay(true), ec);
    backoff = cfg.backoff_initial;
    if (ever_connected) ++reconnects;
    ever_connected = true;
    // Per-session settings of the controller, restored on every (re)connection.
    dialect::Command identify;
    identify.op = dialect::Op::identify;
    auto idn = transact_raw(identify, nullptr, nullptr);
    if (!idn) return fail("no identification: " + idn.error().message);
    if (idn->kind != dialect::Reply::Kind::identity) return fail("identification refused: " + idn->code + " " + idn->text);
    if (cfg.reply_checksum && lang().has_reply_checksum) {
      checksum_on = true;  // the reply to this command already carries the checksum
      dialect::Command on;
      on.op = dialect::Op::checksum;
      on.flag = true;
      auto r = transact_raw(on, nullptr, nullptr);
      if (!r) return fail("cannot enable reply checksums: " + r.error().message);
      if (r->kind != dialect::Reply::Kind::ok) return fail("table refused reply checksums: " + r->code + " " + r->text);
    }
    return success();
  }

  // One line out, one line back, on an open link.
  Result<dialect::Reply> transact_raw(const dialect::Command& c, std::int64_t* t_send, std::int64_t* t_recv) {
    const std::string body = dialect::format_command(lang(), c);
    if (!rx.empty()) {
      close_link("unsolicited data from the table");
      return {DriverErrc::protocol_error, who() + ": unsolicited data before '" + body + "'"};
    }
    std::string out = body + lang().line_end;
    bool wrote = false, read = false;
    error_code wec, rec;
    std::size_t n = 0;
    std::int64_t recv_ns = 0;
    // Stamped before the write: Asio sends at once when it can, inside async_write, and a thread
    // descheduled between that send and a later stamp made a read look instantaneous (3 us round
    // trip, its midpoint 890 us late) and the clock model took it as its best point (a
    // table-to-IMU misalignment of 0.3-2 ms on a loaded machine).
    const std::int64_t send_ns = host_time_ns();
    asio::async_write(socket, asio::buffer(out), [&](const error_code& e, std::size_t) {
      wec = e;
      wrote = true;
    });
    asio::async_read_until(socket, asio::dynamic_buffer(rx, dialect::kMaxLineBytes + 2), '\n',
                           [&](const error_code& e, std::size_t len) {
                             recv_ns = host_time_ns();
                             rec = e;
                             n = len;
                             read = true;
                           });
    if (!run_until(read, cfg.response_timeout)) {
      close_link("no reply to '" + body + "'");
      return {DriverErrc::timeout, who() + ": no reply to '" + body + "' within " + std::to_string(cfg.response_timeout.count()) + " ms"};
    }
    if (!wrote) run_until(wrote, cfg.response_timeout);
    if (rec || wec) {
      const error_code& e = rec ? rec : wec;
      const bool too_long = e == asio::error::not_found;
      close_link(e.message());
      if (too_long) return {DriverErrc::protocol_error, who() + ": reply longer than " + std::to_string(dialect::kMaxLineBytes) + " bytes"};
      return {DriverErrc::connection_lost, who() + ": connection lost during '" + body + "': " + e.message()};
    }
    std::string line = rx.substr(0, n - 1);
    rx.erase(0, n);
    if (t_send) *t_send = send_ns;
    if (t_recv) *t_recv = recv_ns;
    auto reply = dialect::parse_reply(lang(), line, dialect::reply_kind_of(c.op), checksum_on);
    if (!reply) {
      // Resynchronise on a fresh connection rather than guess where the next reply starts.
      close_link("garbled reply");
      return {reply.error().code, who() + ": " + reply.error().message};
    }
    return reply;
  }

  Result<dialect::Reply> transact(const dialect::Command& c, std::int64_t* t_send = nullptr, std::int64_t* t_recv = nullptr) {
    if (state == DeviceState::disconnected) return {DriverErrc::invalid_state, who() + ": not connected"};
    if (auto r = open_link(false); !r) return r.error();
    return transact_raw(c, t_send, t_recv);
  }

  // A command answered by the dialect's "ok"; an error reply becomes its typed error (a reply of
  // another kind is a garbled reply: parse_reply refuses it and the link restarts).
  Result<void> command(const dialect::Command& c) {
    auto r = transact(c);
    if (!r) return r.error();
    if (r->kind == dialect::Reply::Kind::ok) return success();
    return error_of(*r, c);
  }

  DriverError error_of(const dialect::Reply& r, const dialect::Command& c) const {
    DriverErrc code = DriverErrc::device_rejected;
    switch (r.refusal) {
      case dialect::Refusal::interlock_open: code = DriverErrc::interlock_open; break;
      case dialect::Refusal::limit_exceeded: code = DriverErrc::limit_exceeded; break;
      case dialect::Refusal::axis_fault: code = DriverErrc::axis_fault; break;
      case dialect::Refusal::watchdog_expired: code = DriverErrc::watchdog_expired; break;
      case dialect::Refusal::wrong_mode: code = DriverErrc::invalid_state; break;
      default: break;
    }
    return {code, who() + ": '" + dialect::format_command(lang(), c) + "' refused: " + r.code + " " + r.text};
  }

  Result<void> check_axis(int axis) const {
    if (axis < 0 || axis >= kTableAxes)
      return {DriverErrc::invalid_argument, who() + ": axis " + std::to_string(axis) + " (expected 0 outer, 1 middle, 2 inner)"};
    return success();
  }

  Result<TableStatus> status() {
    dialect::Command c;
    c.op = dialect::Op::read_status;
    auto r = transact(c);
    if (!r) return r.error();
    if (r->kind == dialect::Reply::Kind::error) return error_of(*r, c);
    TableStatus st;
    st.t_ns = host_time_ns();
    st.interlock = r->interlock;
    for (std::size_t k = 0; k < 3; ++k) {
      st.axes[k].mode = r->modes[k];
      st.axes[k].at_limit = r->flags[k].at_limit;
      st.axes[k].fault = r->flags[k].fault;
      st.axes[k].watchdog_expired = r->flags[k].watchdog_expired;
      st.axes[k].moving = r->flags[k].moving;
    }
    return st;
  }
};

TcpTable::TcpTable(TcpTableConfig config) : impl_(std::make_unique<Impl>(std::move(config))) {}
TcpTable::~TcpTable() {
  std::lock_guard lock(impl_->mutex);
  impl_->close_link("driver destroyed");
}

std::string TcpTable::describe() const { return impl_->who(); }

DeviceState TcpTable::state() const {
  std::lock_guard lock(impl_->mutex);
  if (impl_->state != DeviceState::disconnected && !impl_->socket.is_open()) return DeviceState::faulted;
  return impl_->state;
}

std::uint64_t TcpTable::reconnects() const {
  std::lock_guard lock(impl_->mutex);
  return impl_->reconnects;
}

ClockModelState TcpTable::clock_model() const {
  std::lock_guard lock(impl_->mutex);
  return impl_->clock.state();
}

Result<void> TcpTable::connect() {
  std::lock_guard lock(impl_->mutex);
  if (auto r = impl_->open_link(true); !r) return r;
  if (impl_->state == DeviceState::disconnected) impl_->state = DeviceState::connected;
  return success();
}

Result<void> TcpTable::configure() {
  std::lock_guard lock(impl_->mutex);
  Impl& m = *impl_;
  if (m.state == DeviceState::disconnected) return {DriverErrc::invalid_state, m.who() + ": configure before connect"};
  for (int a = 0; a < 3; ++a)
    for (int mode = 0; mode < 4; ++mode) {
      const auto& l = m.cfg.limits[static_cast<std::size_t>(a)][static_cast<std::size_t>(mode)];
      if (!l) continue;
      dialect::Command c;
      c.axis = a;
      c.mode = static_cast<TableMode>(mode);
      c.op = dialect::Op::limit_position;
      c.args = {l->min_deg, l->max_deg, 0.0};
      if (auto r = m.command(c); !r) return r;
      c.op = dialect::Op::limit_rate;
      c.args = {l->rate_dps, 0.0, 0.0};
      if (auto r = m.command(c); !r) return r;
      c.op = dialect::Op::limit_accel;
      c.args = {l->accel_dps2, 0.0, 0.0};
      if (auto r = m.command(c); !r) return r;
    }
  if (m.cfg.watchdog_s > 0.0) {
    dialect::Command c;
    c.op = dialect::Op::watchdog;
    c.args[0] = m.cfg.watchdog_s;
    if (auto r = m.command(c); !r) return r;
  }
  auto st = m.status();
  if (!st) return st.error();
  m.state = DeviceState::configured;
  return success();
}

Result<void> TcpTable::activate() {
  std::lock_guard lock(impl_->mutex);
  Impl& m = *impl_;
  if (m.state != DeviceState::configured && m.state != DeviceState::active)
    return {DriverErrc::invalid_state, m.who() + ": activate before configure"};
  dialect::Command c;
  c.op = dialect::Op::interlock_close;
  if (auto r = m.command(c); !r) return r;
  m.state = DeviceState::active;
  return success();
}

Result<void> TcpTable::safe_stop() {
  std::lock_guard lock(impl_->mutex);
  Impl& m = *impl_;
  if (m.state == DeviceState::disconnected) return success();
  // Every axis off (the table brakes it to rest), wait for rest, then open the interlock. Each
  // step is attempted even if an earlier one failed; the first error is reported.
  Result<void> first = success();
  for (int a = 0; a < 3; ++a) {
    dialect::Command c;
    c.op = dialect::Op::mode;
    c.axis = a;
    c.mode = TableMode::off;
    if (auto r = m.command(c); !r && first) first = r;
  }
  const auto until = Clock::now() + m.cfg.safe_stop_timeout;
  for (;;) {
    auto st = m.status();
    if (st) {
      bool moving = false;
      for (const AxisStatus& s : st->axes) moving = moving || s.moving;
      if (!moving) break;
    } else if (st.code() == DriverErrc::not_connected || st.code() == DriverErrc::connect_failed) {
      if (first) first = st.error();  // unreachable: rest cannot be verified
      break;
    }
    if (Clock::now() > until) {
      if (first) first = Result<void>(DriverErrc::timeout, m.who() + ": axes still moving after " +
                                                                 std::to_string(m.cfg.safe_stop_timeout.count()) + " ms");
      break;
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }
  dialect::Command open;
  open.op = dialect::Op::interlock_open;
  if (auto r = m.command(open); !r && first) first = r;
  if (first) m.state = DeviceState::configured;
  return first;
}

void TcpTable::disconnect() noexcept {
  std::lock_guard lock(impl_->mutex);
  impl_->close_link("disconnected");
  impl_->state = DeviceState::disconnected;
}

Result<void> TcpTable::interlock_close() {
  std::lock_guard lock(impl_->mutex);
  dialect::Command c;
  c.op = dialect::Op::interlock_close;
  return impl_->command(c);
}

Result<void> TcpTable::interlock_open() {
  std::lock_guard lock(impl_->mutex);
  dialect::Command c;
  c.op = dialect::Op::interlock_open;
  return impl_->command(c);
}

Result<void> TcpTable::interlock_reset() {
  std::lock_guard lock(impl_->mutex);
  dialect::Command c;
  c.op = dialect::Op::interlock_reset;
  return impl_->command(c);
}

Result<void> TcpTable::set_mode(int axis, TableMode mode) {
  std::lock_guard lock(impl_->mutex);
  if (auto r = impl_->check_axis(axis); !r) return r;
  dialect::Command c;
  c.op = dialect::Op::mode;
  c.axis = axis;
  c.mode = mode;
  return impl_->command(c);
}

Result<void> TcpTable::demand_position(int axis, double angle_deg) {
  std::lock_guard lock(impl_->mutex);
  if (auto r = impl_->check_axis(axis); !r) return r;
  if (!std::isfinite(angle_deg)) return {DriverErrc::invalid_argument, impl_->who() + ": position demand is not a number"};
  dialect::Command c;
  c.op = dialect::Op::demand_position;
  c.axis = axis;
  c.args[0] = angle_deg;
  return impl_->command(c);
}

Result<void> TcpTable::demand_rate(int axis, double rate_dps) {
  std::lock_guard lock(impl_->mutex);
  if (auto r = impl_->check_axis(axis); !r) return r;
  if (!std::isfinite(rate_dps)) return {DriverErrc::invalid_argument, impl_->who() + ": rate demand is not a number"};
  dialect::Command c;
  c.op = dialect::Op::demand_rate;
  c.axis = axis;
  c.args[0] = rate_dps;
  return impl_->command(c);
}

Result<void> TcpTable::demand_oscillation(int axis, const OscillationDemand& d) {
  std::lock_guard lock(impl_->mutex);
  if (auto r = impl_->check_axis(axis); !r) return r;
  if (!std::isfinite(d.amplitude_deg) || !std::isfinite(d.frequency_hz) || !std::isfinite(d.phase_deg) ||
      d.amplitude_deg < 0.0 || d.frequency_hz < 0.0)
    return {DriverErrc::invalid_argument, impl_->who() + ": oscillation needs amplitude >= 0, frequency >= 0, finite phase"};
  dialect::Command c;
  c.op = dialect::Op::demand_oscillation;
  c.axis = axis;
  c.args = {d.amplitude_deg, d.frequency_hz, d.phase_deg};
  return impl_->command(c);
}

Result<void> TcpTable::set_limits(int axis, TableMode mode, const AxisLimitSetting& l) {
  std::lock_guard lock(impl_->mutex);
  if (auto r = impl_->check_axis(axis); !r) return r;
  if (!(l.min_deg < l.max_deg) || !(l.rate_dps > 0.0) || !(l.accel_dps2 > 0.0) || !std::isfinite(l.rate_dps) ||
      !std::isfinite(l.accel_dps2))
    return {DriverErrc::invalid_argument, impl_->who() + ": limits need min < max and positive finite rate and acceleration"};
  dialect::Command c;
  c.axis = axis;
  c.mode = mode;
  c.op = dialect::Op::limit_position;
  c.args = {l.min_deg, l.max_deg, 0.0};
  if (auto r = impl_->command(c); !r) return r;
  c.op = dialect::Op::limit_rate;
  c.args = {l.rate_dps, 0.0, 0.0};
  if (auto r = impl_->command(c); !r) return r;
  c.op = dialect::Op::limit_accel;
  c.args = {l.accel_dps2, 0.0, 0.0};
  return impl_->command(c);
}

Result<void> TcpTable::set_watchdog(double period_s) {
  std::lock_guard lock(impl_->mutex);
  if (!(period_s >= 0.0) || !std::isfinite(period_s))
    return {DriverErrc::invalid_argument, impl_->who() + ": watchdog period must be >= 0"};
  dialect::Command c;
  c.op = dialect::Op::watchdog;
  c.args[0] = period_s;
  return impl_->command(c);
}

Result<TablePositions> TcpTable::read_positions() {
  std::lock_guard lock(impl_->mutex);
  Impl& m = *impl_;
  dialect::Command c;
  c.op = dialect::Op::read_positions;
  std::int64_t t_send = 0, t_recv = 0;
  auto r = m.transact(c, &t_send, &t_recv);
  if (!r) return r.error();
  if (r->kind == dialect::Reply::Kind::error) return m.error_of(*r, c);
  TablePositions p;
  p.device_time_us = r->time_us;
  p.angle_deg = r->angle_deg;
  p.rate_dps = r->rate_dps;
  p.round_trip_ns = t_recv - t_send;
  // The controller sampled somewhere between send and receive: the midpoint, with an error of at
  // most half the round trip; the fit keeps the reads with the shortest round trips.
  const std::int64_t mid = t_send + p.round_trip_ns / 2;
  const std::int64_t dev_ns = r->time_us * 1000;
  m.clock.add(dev_ns, mid, p.round_trip_ns);
  p.t_ns = m.clock.map(dev_ns);
  return p;
}

Result<TableStatus> TcpTable::read_status() {
  std::lock_guard lock(impl_->mutex);
  return impl_->status();
}

}  // namespace imucal::drivers
