#include "sim/sim_table.hpp"

#include <atomic>
#include <future>
#include <cmath>
#include <list>
#include <mutex>
#include <stdexcept>
#include <thread>

#include <boost/asio/io_context.hpp>
#include <boost/asio/ip/tcp.hpp>
#include <boost/asio/post.hpp>
#include <boost/asio/read_until.hpp>
#include <boost/asio/steady_timer.hpp>
#include <boost/asio/write.hpp>


namespace imucal::sim {

// The simulated devices speak the drivers' types and protocols.
using namespace imucal::drivers;

namespace asio = boost::asio;
using asio::ip::tcp;
using boost::system::error_code;

struct SimTable::Impl {
  SimWorld& world;
  SimTableConfig cfg;
  asio::io_context io;
  tcp::acceptor acceptor{io};
  std::thread thread;
  int port = 0;
  std::atomic<std::uint64_t> commands{0};

  std::mutex fault_mutex;
  std::chrono::milliseconds delay{0};
  int corrupt = 0;
  bool silent = false;

  // One connection; lives as long as an operation holds it. Everything runs on the one io
  // thread, so no strand is needed.
  struct Session : std::enable_shared_from_this<Session> {
    Impl& impl;
    tcp::socket socket;
    std::string rx;
    std::string tx;
    asio::steady_timer timer;
    bool checksum = false;
    Session(Impl& i, tcp::socket s) : impl(i), socket(std::move(s)), timer(i.io) {}

    void read() {
      auto self = shared_from_this();
      asio::async_read_until(socket, asio::dynamic_buffer(rx, dialect::kMaxLineBytes + 2), '\n',
                             [self](const error_code& ec, std::size_t n) { self->on_line(ec, n); });
    }

    void on_line(const error_code& ec, std::size_t n) {
      if (ec == asio::error::not_found) {
        // A line longer than any command: answer and hang up, as the framing is lost.
        dialect::Reply too_long;
        too_long.kind = dialect::Reply::Kind::error;
        too_long.refusal = dialect::Refusal::syntax;
        too_long.text = "line too long";
        tx = dialect::frame_line(impl.cfg.dialect, dialect::format_reply(impl.cfg.dialect, too_long), checksum);
        auto self = shared_from_this();
        asio::async_write(socket, asio::buffer(tx), [self](const error_code&, std::size_t) {
          error_code ignored;
          self->socket.close(ignored);
        });
        return;
      }
      if (ec) {
        error_code ignored;
        socket.close(ignored);
        return;
      }
      std::string line = rx.substr(0, n - 1);
      rx.erase(0, n);
      ++impl.commands;
      std::chrono::milliseconds d;
      bool mute, corrupt_this;
      {
        std::lock_guard lock(impl.fault_mutex);
        d = impl.delay;
        mute = impl.silent;
        corrupt_this = impl.corrupt > 0;
        if (corrupt_this) --impl.corrupt;
      }
      const std::string body = impl.execute(*this, line);
      if (mute) {
        read();
        return;
      }
      tx = dialect::frame_line(impl.cfg.dialect, body, checksum);
      if (corrupt_this && tx.size() > 1) {
        // Flip bits in one byte of the body, mid-line, keeping it printable ASCII so that only
        // the content (not the framing) is damaged.
        const std::size_t at = (tx.size() - 1) / 2;
        char c = static_cast<char>(tx[at] ^ 0x01);
        if (c == '\n' || c == '\r' || c < 0x20 || c > 0x7E) c = static_cast<char>(tx[at] ^ 0x02);
        tx[at] = c;
      }
      auto self = shared_from_this();
      if (d.count() > 0) {
        timer.expires_after(d);
        timer.async_wait([self](const error_code& tec) {
          if (!tec) self->write();
        });
      } else {
        write();
      }
    }

    void write() {
      auto self = shared_from_this();
      asio::async_write(socket, asio::buffer(tx), [self](const error_code& ec, std::size_t) {
        if (!ec) self->read();
      });
    }
  };
  std::list<std::weak_ptr<Session>> sessions;

  Impl(SimWorld& w, SimTableConfig c) : world(w), cfg(std::move(c)) {}

  std::int64_t device_time_us(double world_s) const noexcept {
    const double clock_s = world.clock_s(world_s);  // the controller's clock ticks in host seconds
    return static_cast<std::int64_t>(std::llround(clock_s * 1e6 * (1.0 + cfg.clock_drift_ppm * 1e-6))) + cfg.clock_offset_us;
  }

  void accept() {
    acceptor.async_accept([this](const error_code& ec, tcp::socket s) {
      if (ec) return;  // acceptor closed
      error_code ignored;
      s.set_option(tcp::no_delay(true), ignored);
      auto session = std::make_shared<Session>(*this, std::move(s));
      sessions.remove_if([](const std::weak_ptr<Session>& w) { return w.expired(); });
      sessions.push_back(session);
      session->read();
      accept();
    });
  }

  // Executes one command line on the world; returns the reply body.
  std::string execute(Session& session, const std::string& line) {
    const dialect::Dialect& d = cfg.dialect;
    const auto parsed = dialect::parse_command(d, line);
    dialect::Reply reply;
    if (const auto* e = std::get_if<dialect::ParseError>(&parsed)) {
      reply.kind = dialect::Reply::Kind::error;
      reply.refusal = e->refusal;
      reply.text = e->text;
      return dialect::format_reply(d, reply);
    }
    const dialect::Command& c = std::get<dialect::Command>(parsed);
    switch (c.op) {
      case dialect::Op::identify:
        reply.kind = dialect::Reply::Kind::identity;
        reply.text = cfg.identity;
        return dialect::format_reply(d, reply);
      case dialect::Op::checksum:
        session.checksum = c.flag;
        return dialect::format_reply(d, reply);
      case dialect::Op::read_positions:
        world.with_servo([&](TableServo& s, double t) {
          const auto smp = s.sample(t);
          reply.kind = dialect::Reply::Kind::positions;
          reply.time_us = device_time_us(t);
          for (std::size_t k = 0; k < 3; ++k) {
            reply.angle_deg[k] = smp[k].angle_deg;
            reply.rate_dps[k] = smp[k].rate_dps;
          }
        });
        return dialect::format_reply(d, reply);
      case dialect::Op::read_status:
        world.with_servo([&](TableServo& s, double t) {
          const TableStatus st = s.status(t);
          reply.kind = dialect::Reply::Kind::status;
          reply.time_us = device_time_us(t);
          reply.interlock = st.interlock;
          for (std::size_t k = 0; k < 3; ++k) {
            reply.modes[k] = st.axes[k].mode;
            reply.flags[k] = {st.axes[k].at_limit, st.axes[k].fault, st.axes[k].watchdog_expired, st.axes[k].moving};
          }
        });
        return dialect::format_reply(d, reply);
      default: break;
    }
    const ServoResult r = world.with_servo([&](TableServo& s, double t) -> ServoResult {
      switch (c.op) {
        case dialect::Op::interlock_close: return s.interlock_close(t);
        case dialect::Op::interlock_open: return s.interlock_open(t);
        case dialect::Op::interlock_reset: return s.interlock_reset(t);
        case dialect::Op::mode: return s.set_mode(t, c.axis, c.mode);
        case dialect::Op::demand_position: return s.demand_position(t, c.axis, c.args[0]);
        case dialect::Op::demand_rate: return s.demand_rate(t, c.axis, c.args[0]);
        case dialect::Op::demand_oscillation: return s.demand_oscillation(t, c.axis, {c.args[0], c.args[1], c.args[2]});
        case dialect::Op::limit_position: return s.set_limit_position(t, c.axis, c.mode, c.args[0], c.args[1]);
        case dialect::Op::limit_rate: return s.set_limit_rate(t, c.axis, c.mode, c.args[0]);
        case dialect::Op::limit_accel: return s.set_limit_accel(t, c.axis, c.mode, c.args[0]);
        case dialect::Op::watchdog: return s.set_watchdog(t, c.args[0]);
        default: return {dialect::Refusal::syntax, "unsupported"};
      }
    });
    if (!r.ok()) {
      reply.kind = dialect::Reply::Kind::error;
      reply.refusal = r.refusal;
      reply.text = r.text;
    }
    return dialect::format_reply(d, reply);
  }

  void close_all() {
    for (auto& w : sessions)
      if (auto s = w.lock()) {
        error_code ignored;
        s->timer.cancel();
        s->socket.close(ignored);
      }
    sessions.clear();
  }
};

SimTable::SimTable(SimWorld& world, SimTableConfig config) : impl_(std::make_unique<Impl>(world, std::move(config))) {
  Impl& m = *impl_;
  error_code ec;
  const tcp::endpoint ep(asio::ip::address_v4::loopback(), static_cast<unsigned short>(m.cfg.port));
  m.acceptor.open(ep.protocol(), ec);
  if (!ec) m.acceptor.set_option(tcp::acceptor::reuse_address(true), ec);
  if (!ec) m.acceptor.bind(ep, ec);
  if (!ec) m.acceptor.listen(8, ec);
  if (ec) throw std::runtime_error("simulated table: cannot listen on 127.0.0.1:" + std::to_string(m.cfg.port) + ": " + ec.message());
  m.port = m.acceptor.local_endpoint(ec).port();
  m.accept();
  m.thread = std::thread([this] { impl_->io.run(); });
}

SimTable::~SimTable() {
  asio::post(impl_->io, [this] {
    error_code ignored;
    impl_->acceptor.close(ignored);
    impl_->close_all();
  });
  // Pending operations finish with operation_aborted; then run() returns.
  impl_->thread.join();
}

int SimTable::port() const noexcept { return impl_->port; }
std::int64_t SimTable::device_time_us(double world_s) const noexcept { return impl_->device_time_us(world_s); }
std::uint64_t SimTable::commands() const noexcept { return impl_->commands; }

void SimTable::drop_connections() {
  // Synchronously, so that no command sent after this call is answered.
  std::promise<void> done;
  asio::post(impl_->io, [this, &done] {
    impl_->close_all();
    done.set_value();
  });
  done.get_future().wait();
}

void SimTable::set_reply_delay(std::chrono::milliseconds delay) {
  std::lock_guard lock(impl_->fault_mutex);
  impl_->delay = delay;
}
void SimTable::corrupt_next_replies(int count) {
  std::lock_guard lock(impl_->fault_mutex);
  impl_->corrupt = count;
}
void SimTable::set_silent(bool silent) {
  std::lock_guard lock(impl_->fault_mutex);
  impl_->silent = silent;
}
void SimTable::trip_interlock() {
  impl_->world.with_servo([](TableServo& s, double t) { return s.interlock_open(t); });
}

}  // namespace imucal::sim
