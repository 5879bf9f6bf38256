#include "sim/sim_chamber.hpp"

#include <algorithm>
#include <atomic>
#include <cerrno>
#include <cmath>
#include <cstring>
#include <mutex>
#include <optional>
#include <stdexcept>
#include <thread>
#include <vector>

#include <arpa/inet.h>
#include <modbus/modbus.h>
#include <netinet/in.h>
#include <sys/select.h>
#include <sys/socket.h>
#include <unistd.h>

namespace imucal::sim {

// The simulated devices speak the drivers' types and protocols.
using namespace imucal::drivers;

using Clock = std::chrono::steady_clock;

struct SimChamber::Impl {
  SimChamberConfig cfg;
  modbus_t* ctx = nullptr;
  modbus_mapping_t* mapping = nullptr;
  int listen_fd = -1;
  int port = 0;
  std::vector<int> clients;  // server thread only
  std::thread thread;
  std::atomic<bool> stop{false};
  std::atomic<std::uint64_t> requests{0};

  mutable std::mutex mutex;  // everything below
  double pv_C, sp_C, wsp_C;
  double ramp_rate_C_per_min = 0.0;
  bool control_on = true;
  TemperatureUnit unit;
  std::vector<std::optional<std::uint16_t>> alarm_raw;
  Clock::time_point last_update = Clock::now();
  bool drop_pending = false;
  std::chrono::milliseconds delay{0};
  int corrupt = 0;
  bool silent = false;
  double reading_offset_C = 0.0;  // a sensor fault: added to the process value served
  std::vector<bool> coils;        // the digital outputs as written
  bool outputs_forced = false;
  std::vector<CoilChange> coil_changes;
  Clock::time_point started = Clock::now();

  explicit Impl(SimChamberConfig c)
      : cfg(std::move(c)), pv_C(cfg.initial_C), sp_C(cfg.initial_C), wsp_C(cfg.initial_C), unit(cfg.unit) {
    if (!cfg.map.units) unit = cfg.map.fixed_unit;
    alarm_raw.resize(cfg.map.alarms.size());
    coils.assign(static_cast<std::size_t>(std::max(cfg.digital_outputs, 0)), false);
  }

  // Coil writes (function 5 or 15) taken into the outputs before the reply, as registers are.
  void absorb_coil_writes(const std::uint8_t* query, int h, int rc) {
    const std::uint8_t function = query[h];
    if (function != 0x05 && function != 0x0F) return;
    const int first = (query[h + 1] << 8) | query[h + 2];
    std::vector<bool> values;
    if (function == 0x05) {
      values.push_back(query[h + 3] == 0xFF);
    } else {
      const int count = (query[h + 3] << 8) | query[h + 4];
      for (int i = 0; i < count && h + 6 + i / 8 < rc; ++i) values.push_back(((query[h + 6 + i / 8] >> (i % 8)) & 1) != 0);
    }
    std::lock_guard lock(mutex);
    if (outputs_forced) return;
    const double t_s = std::chrono::duration<double>(Clock::now() - started).count();
    for (std::size_t i = 0; i < values.size(); ++i) {
      const auto k = static_cast<std::size_t>(first) + i;
      if (k >= coils.size() || coils[k] == values[i]) continue;
      coils[k] = values[i];
      coil_changes.push_back({t_s, static_cast<int>(k), values[i]});
    }
  }

  // First-order air temperature towards the working set point; the working set point follows
  // the set point at the ramp rate (when the map has a ramp register and the rate is non-zero).
  void update(Clock::time_point now) {
    const double dt = std::chrono::duration<double>(now - last_update).count() * cfg.time_scale;  // world s
    last_update = now;
    if (dt <= 0.0) return;
    if (cfg.map.ramp_rate_per_min && ramp_rate_C_per_min > 0.0) {
      const double step = ramp_rate_C_per_min / 60.0 * dt;
      wsp_C = sp_C > wsp_C ? std::min(sp_C, wsp_C + step) : std::max(sp_C, wsp_C - step);
    } else {
      wsp_C = sp_C;
    }
    const double target = control_on ? wsp_C : cfg.ambient_C;
    pv_C += (target - pv_C) * (1.0 - std::exp(-dt / cfg.time_constant_s));
  }

  void put_value(int address, double value_in_unit) {
    const auto regs = encode_value(cfg.map, value_in_unit);
    if (!regs) return;
    for (std::size_t i = 0; i < regs->size(); ++i) mapping->tab_registers[static_cast<std::size_t>(address) + i] = (*regs)[i];
  }

  void write_registers() {
    const RegisterMap& m = cfg.map;
    put_value(m.process_value, celsius_to_unit(pv_C + reading_offset_C, unit));
    put_value(m.setpoint, celsius_to_unit(sp_C, unit));
    if (m.working_setpoint) put_value(*m.working_setpoint, celsius_to_unit(wsp_C, unit));
    if (m.ramp_rate_per_min) put_value(*m.ramp_rate_per_min, celsius_delta_to_unit(ramp_rate_C_per_min, unit));
    if (m.control_mode)
      mapping->tab_registers[m.control_mode->address] = control_on ? m.control_mode->auto_value : m.control_mode->off_value;
    if (m.units)
      mapping->tab_registers[m.units->address] = unit == TemperatureUnit::celsius ? m.units->celsius_value : m.units->fahrenheit_value;
    for (std::size_t i = 0; i < m.alarms.size(); ++i) {
      const AlarmRegister& a = m.alarms[i];
      const std::uint16_t normal = a.mask ? 0 : a.normal.front();
      mapping->tab_registers[a.address] = alarm_raw[i].value_or(normal);
    }
  }

  // After a write request: take the written registers into the model.
  void absorb_writes(int first, int count) {
    const RegisterMap& m = cfg.map;
    auto touched = [&](int address, int n) { return address < first + count && first < address + n; };
    auto value_at = [&](int address) {
      std::vector<std::uint16_t> regs(static_cast<std::size_t>(m.registers_per_value()));
      for (std::size_t i = 0; i < regs.size(); ++i) regs[i] = mapping->tab_registers[static_cast<std::size_t>(address) + i];
      return decode_value(m, regs);
    };
    if (m.units && touched(m.units->address, 1)) {
      const std::uint16_t v = mapping->tab_registers[m.units->address];
      if (v == m.units->celsius_value) unit = TemperatureUnit::celsius;
      if (v == m.units->fahrenheit_value) unit = TemperatureUnit::fahrenheit;
    }
    if (touched(m.setpoint, m.registers_per_value()))
      if (const auto v = value_at(m.setpoint)) sp_C = unit_to_celsius(*v, unit);
    if (m.ramp_rate_per_min && touched(*m.ramp_rate_per_min, m.registers_per_value()))
      if (const auto v = value_at(*m.ramp_rate_per_min))
        ramp_rate_C_per_min = std::max(0.0, unit == TemperatureUnit::fahrenheit ? *v * 5.0 / 9.0 : *v);
    if (m.control_mode && touched(m.control_mode->address, 1))
      control_on = mapping->tab_registers[m.control_mode->address] == m.control_mode->auto_value;
  }

  void close_client(int fd) {
    ::close(fd);
    clients.erase(std::remove(clients.begin(), clients.end(), fd), clients.end());
  }

  void sleep_interruptible(std::chrono::milliseconds d) {
    const auto until = Clock::now() + d;
    while (!stop && Clock::now() < until) std::this_thread::sleep_for(std::chrono::milliseconds(5));
  }

  void serve(int fd) {
    modbus_set_socket(ctx, fd);
    std::uint8_t query[MODBUS_TCP_MAX_ADU_LENGTH];
    const int rc = modbus_receive(ctx, query);
    if (rc == -1) {
      close_client(fd);
      return;
    }
    if (rc == 0) return;
    ++requests;
    bool is_silent, drop, do_corrupt;
    std::chrono::milliseconds d;
    {
      std::lock_guard lock(mutex);
      is_silent = silent;
      drop = drop_pending;
      d = delay;
      do_corrupt = corrupt > 0;
      if (do_corrupt) --corrupt;
    }
    if (drop) return;  // the loop closes it
    if (is_silent) return;
    if (d.count() > 0) sleep_interruptible(d);
    {
      std::lock_guard lock(mutex);
      if (drop_pending) return;
      update(Clock::now());
      write_registers();
      for (std::size_t i = 0; i < coils.size(); ++i) mapping->tab_bits[i] = coils[i] ? 1 : 0;
    }
    const int h = modbus_get_header_length(ctx);
    const std::uint8_t function = query[h];
    if (do_corrupt) {
      // An exception reply under a transaction id that is not the request's: the client must
      // reject it (libmodbus: "Invalid data") rather than take anything from it.
      const std::uint8_t bad[] = {query[0], static_cast<std::uint8_t>(query[1] ^ 0x5A), 0, 0, 0, 3, query[6],
                                  static_cast<std::uint8_t>(function | 0x80), 0x04};
      if (::send(fd, bad, sizeof bad, MSG_NOSIGNAL) < 0) close_client(fd);
      return;
    }
    if (function == 0x06 || function == 0x10) {
      // Take a write into the model before acknowledging it, as a controller does: once the
      // client has its reply, the new set point is in force.
      const int first = (query[h + 1] << 8) | query[h + 2];
      const int count = function == 0x06 ? 1 : ((query[h + 3] << 8) | query[h + 4]);
      const int data = function == 0x06 ? h + 3 : h + 6;
      if (first >= 0 && count >= 1 && first + count <= mapping->nb_registers && data + 2 * count <= rc) {
        std::lock_guard lock(mutex);
        for (int i = 0; i < count; ++i)
          mapping->tab_registers[first + i] =
              static_cast<std::uint16_t>((query[data + 2 * i] << 8) | query[data + 2 * i + 1]);
        absorb_writes(first, count);
      }
    }
    absorb_coil_writes(query, h, rc);
    if (modbus_reply(ctx, query, rc, mapping) == -1) close_client(fd);
  }

  void run() {
    while (!stop) {
      fd_set rd;
      FD_ZERO(&rd);
      FD_SET(listen_fd, &rd);
      int maxfd = listen_fd;
      for (int c : clients) {
        FD_SET(c, &rd);
        maxfd = std::max(maxfd, c);
      }
      timeval tv{0, 20000};
      const int n = ::select(maxfd + 1, &rd, nullptr, nullptr, &tv);
      {
        std::lock_guard lock(mutex);
        update(Clock::now());
        if (drop_pending) {
          for (int c : clients) ::close(c);
          clients.clear();
          drop_pending = false;
          continue;
        }
      }
      if (n <= 0) continue;
      if (FD_ISSET(listen_fd, &rd)) {
        const int c = ::accept(listen_fd, nullptr, nullptr);
        if (c >= 0) clients.push_back(c);
      }
      const std::vector<int> ready = clients;
      for (int c : ready)
        if (FD_ISSET(c, &rd) && std::find(clients.begin(), clients.end(), c) != clients.end()) serve(c);
    }
  }
};

SimChamber::SimChamber(SimChamberConfig config) : impl_(std::make_unique<Impl>(std::move(config))) {
  Impl& m = *impl_;
  m.ctx = modbus_new_tcp("127.0.0.1", m.cfg.port);
  if (!m.ctx) throw std::runtime_error(std::string("simulated chamber: modbus_new_tcp: ") + modbus_strerror(errno));
  m.mapping = modbus_mapping_new(std::max(m.cfg.digital_outputs, 0), 0, m.cfg.map.address_end(), 0);
  if (!m.mapping) {
    modbus_free(m.ctx);
    throw std::runtime_error(std::string("simulated chamber: register bank: ") + modbus_strerror(errno));
  }
  m.listen_fd = modbus_tcp_listen(m.ctx, 8);
  if (m.listen_fd < 0) {
    const std::string why = modbus_strerror(errno);
    modbus_mapping_free(m.mapping);
    modbus_free(m.ctx);
    throw std::runtime_error("simulated chamber: listen on 127.0.0.1:" + std::to_string(m.cfg.port) + ": " + why);
  }
  sockaddr_in addr{};
  socklen_t len = sizeof addr;
  ::getsockname(m.listen_fd, reinterpret_cast<sockaddr*>(&addr), &len);
  m.port = ntohs(addr.sin_port);
  m.write_registers();
  m.thread = std::thread([this] { impl_->run(); });
}

SimChamber::~SimChamber() {
  impl_->stop = true;
  if (impl_->thread.joinable()) impl_->thread.join();
  for (int c : impl_->clients) ::close(c);
  ::close(impl_->listen_fd);
  modbus_mapping_free(impl_->mapping);
  // The context's socket is one of the closed clients (or none): do not let modbus_close touch it.
  modbus_set_socket(impl_->ctx, -1);
  modbus_free(impl_->ctx);
}

int SimChamber::port() const noexcept { return impl_->port; }

double SimChamber::process_C() const {
  std::lock_guard lock(impl_->mutex);
  impl_->update(Clock::now());
  return impl_->pv_C;
}
double SimChamber::setpoint_C() const {
  std::lock_guard lock(impl_->mutex);
  return impl_->sp_C;
}
double SimChamber::working_setpoint_C() const {
  std::lock_guard lock(impl_->mutex);
  impl_->update(Clock::now());
  return impl_->wsp_C;
}
bool SimChamber::control_on() const {
  std::lock_guard lock(impl_->mutex);
  return impl_->control_on;
}
std::uint64_t SimChamber::requests() const { return impl_->requests; }

void SimChamber::set_coil(int address, bool set) {
  std::lock_guard lock(impl_->mutex);
  if (address >= 0 && static_cast<std::size_t>(address) < impl_->coils.size()) {
    impl_->coils[static_cast<std::size_t>(address)] = set;  // served from the next request on
  }
}

void SimChamber::set_outputs_forced(bool forced) {
  std::lock_guard lock(impl_->mutex);
  impl_->outputs_forced = forced;
}

bool SimChamber::coil(int address) const {
  std::lock_guard lock(impl_->mutex);
  return address >= 0 && static_cast<std::size_t>(address) < impl_->coils.size() && impl_->coils[static_cast<std::size_t>(address)];
}

std::vector<CoilChange> SimChamber::coil_changes() const {
  std::lock_guard lock(impl_->mutex);
  return impl_->coil_changes;
}

void SimChamber::set_unit(TemperatureUnit unit) {
  std::lock_guard lock(impl_->mutex);
  if (impl_->cfg.map.units) impl_->unit = unit;
}
void SimChamber::set_alarm(std::size_t index, std::uint16_t raw) {
  std::lock_guard lock(impl_->mutex);
  if (index < impl_->alarm_raw.size()) impl_->alarm_raw[index] = raw;
}
void SimChamber::clear_alarms() {
  std::lock_guard lock(impl_->mutex);
  for (auto& a : impl_->alarm_raw) a.reset();
}
void SimChamber::drop_connections() {
  std::lock_guard lock(impl_->mutex);
  impl_->drop_pending = true;
}
void SimChamber::set_reply_delay(std::chrono::milliseconds delay) {
  std::lock_guard lock(impl_->mutex);
  impl_->delay = delay;
}
void SimChamber::corrupt_next_replies(int count) {
  std::lock_guard lock(impl_->mutex);
  impl_->corrupt = count;
}
void SimChamber::set_silent(bool silent) {
  std::lock_guard lock(impl_->mutex);
  impl_->silent = silent;
}
void SimChamber::set_reading_offset(double delta_C) {
  std::lock_guard lock(impl_->mutex);
  impl_->reading_offset_C = delta_C;
}

}  // namespace imucal::sim
