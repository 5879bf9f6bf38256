#include "drivers/modbus_chamber.hpp"

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstring>
#include <mutex>
#include <vector>

#include <modbus/modbus.h>
#include <nlohmann/json.hpp>

#include "core/json_reader.hpp"

namespace imucal::drivers {

using Clock = std::chrono::steady_clock;

ModbusChamberConfig modbus_chamber_config_from_json(const std::string& json_text) {
  using nlohmann::json;
  json j;
  try {
    j = json::parse(json_text);
  } catch (const json::exception& e) {
    throw std::invalid_argument(std::string("chamber config: not valid JSON: ") + e.what());
  }
  ModbusChamberConfig c;
  ObjectReader r(j, "", ObjectReader::ThrowAtFirst{"chamber config: "});
  if (const auto f = r.string("format"); f && *f != "imucal-chamber/1") r.fail(r.at("format") + " must be \"imucal-chamber/1\"");
  read_modbus_link(r, c);
  const json& map = r.required("map");
  if (map.is_string()) c.map = load_register_map(map.get<std::string>());
  else if (map.is_object()) c.map = register_map_from_json(map.dump());
  else r.fail(r.at("map") + " must be a built-in map's name, a file or an imucal-chamber-map/1 object");
  if (const json* safe = r.get("safe_setpoint_C")) {
    if (safe->is_null()) c.safe_setpoint_C.reset();
    else c.safe_setpoint_C = r.number("safe_setpoint_C");
  }
  if (const json* range = r.get("setpoint_range_C")) {
    if (!range->is_array() || range->size() != 2 || !(*range)[0].is_number() || !(*range)[1].is_number() ||
        !((*range)[0].get<double>() < (*range)[1].get<double>()))
      r.fail(r.at("setpoint_range_C") + " must be [min, max] with min < max");
    c.setpoint_min_C = (*range)[0].get<double>();
    c.setpoint_max_C = (*range)[1].get<double>();
  }
  r.finish();
  if (!c.safe_setpoint_C && !c.map.control_mode)
    r.fail("safe_setpoint_C is null but the map has no control_mode register to switch off");
  return c;
}

struct ModbusChamber::Impl {
  ModbusChamberConfig cfg;
  mutable std::mutex mutex;
  ModbusLink link;  // open while the controller is reachable
  DeviceState state = DeviceState::disconnected;  // the lifecycle state reached

  // Driver-side ramp (maps without a ramp register).
  struct Ramp {
    double start_C, target_C, rate_C_per_s;
    Clock::time_point start;
    double last_written_C;
  };
  std::optional<Ramp> ramp;
  std::optional<double> device_ramp_target_C;  // ramp run by the controller

  explicit Impl(ModbusChamberConfig c)
      : cfg(std::move(c)), link(cfg, cfg.map.slave_id, "chamber " + cfg.address() + " (" + cfg.map.name + ")") {}

  const std::string& who() const { return link.who(); }

  // "what (register 2782..2783)": an exception reply names the register the controller refused,
  // so a wrong map entry is found from the message alone.
  static std::string at_register(const std::string& what, int address, int count) {
    std::string s = what + " (register " + std::to_string(address);
    if (count > 1) s += ".." + std::to_string(address + count - 1);
    return s + ")";
  }

  Result<std::vector<std::uint16_t>> read_regs(int address, int count, const std::string& what) {
    auto ctx = link.open(false);
    if (!ctx) return ctx.error();
    std::vector<std::uint16_t> regs(static_cast<std::size_t>(count));
    errno = 0;
    const int n = modbus_read_registers(*ctx, address, count, regs.data());
    if (n != count) {
      if (n >= 0) {
        errno = EMBBADDATA;
      }
      return link.fail(at_register(what, address, count));
    }
    return regs;
  }

  Result<void> write_regs(int address, const std::vector<std::uint16_t>& regs, const std::string& what) {
    auto ctx = link.open(false);
    if (!ctx) return ctx.error();
    errno = 0;
    const int n = regs.size() == 1 ? modbus_write_register(*ctx, address, regs[0])
                                   : modbus_write_registers(*ctx, address, static_cast<int>(regs.size()), regs.data());
    if (n != (regs.size() == 1 ? 1 : static_cast<int>(regs.size()))) {
      if (n >= 0) {
        errno = EMBBADDATA;
      }
      return link.fail(at_register(what, address, static_cast<int>(regs.size())));
    }
    return success();
  }

  Result<TemperatureUnit> read_unit() {
    if (!cfg.map.units) return cfg.map.fixed_unit;
    auto r = read_regs(cfg.map.units->address, 1, "reading the units register");
    if (!r) return r.error();
    const std::uint16_t v = (*r)[0];
    if (v == cfg.map.units->celsius_value) return TemperatureUnit::celsius;
    if (v == cfg.map.units->fahrenheit_value) return TemperatureUnit::fahrenheit;
    return {DriverErrc::protocol_error, who() + ": units register holds " + std::to_string(v) + ", neither C (" +
                                            std::to_string(cfg.map.units->celsius_value) + ") nor F (" +
                                            std::to_string(cfg.map.units->fahrenheit_value) + ")"};
  }

  // A temperature register in Celsius, checked for plausibility.
  Result<double> read_temperature(int address, TemperatureUnit unit, const char* what) {
    auto r = read_regs(address, cfg.map.registers_per_value(), what);
    if (!r) return r.error();
    const auto v = decode_value(cfg.map, *r);
    if (!v) return {DriverErrc::protocol_error, who() + ": " + what + ": registers hold no finite number"};
    const double c = unit_to_celsius(*v, unit);
    if (c < cfg.map.plausible_min_C || c > cfg.map.plausible_max_C)
      return {DriverErrc::protocol_error, who() + ": " + what + ": implausible value " + std::to_string(c) + " C"};
    return c;
  }

  Result<void> write_temperature(int address, double celsius, TemperatureUnit unit, const char* what) {
    const auto regs = encode_value(cfg.map, celsius_to_unit(celsius, unit));
    if (!regs) return {DriverErrc::invalid_argument, who() + ": " + what + ": " + std::to_string(celsius) + " C cannot be encoded"};
    return write_regs(address, *regs, what);
  }

  Result<std::vector<ChamberAlarm>> read_alarms() {
    std::vector<ChamberAlarm> out;
    for (const AlarmRegister& a : cfg.map.alarms) {
      auto r = read_regs(a.address, 1, "reading alarm '" + a.name + "'");
      if (!r) return r.error();
      if (a.active((*r)[0])) out.push_back({a.name, (*r)[0]});
    }
    return out;
  }

  Result<void> check_setpoint(double c) const {
    if (!std::isfinite(c) || c < cfg.setpoint_min_C || c > cfg.setpoint_max_C)
      return {DriverErrc::invalid_argument, who() + ": set point " + std::to_string(c) + " C outside [" +
                                                std::to_string(cfg.setpoint_min_C) + ", " + std::to_string(cfg.setpoint_max_C) + "] C"};
    return success();
  }

  double resolution_C() const { return cfg.map.encoding == ValueEncoding::scaled_i16 ? 1.0 / cfg.map.scale : 0.01; }

  Result<void> set_control(bool on) {
    if (!cfg.map.control_mode) return success();
    const std::uint16_t v = on ? cfg.map.control_mode->auto_value : cfg.map.control_mode->off_value;
    return write_regs(cfg.map.control_mode->address, {v}, "writing the control mode");
  }

  Result<void> write_device_ramp_rate(double rate_C_per_min, TemperatureUnit unit) {
    if (!cfg.map.ramp_rate_per_min) return success();
    const auto regs = encode_value(cfg.map, celsius_delta_to_unit(rate_C_per_min, unit));
    if (!regs) return {DriverErrc::invalid_argument, who() + ": ramp rate cannot be encoded"};
    return write_regs(*cfg.map.ramp_rate_per_min, *regs, "writing the ramp rate");
  }
};

ModbusChamber::ModbusChamber(ModbusChamberConfig config) : impl_(std::make_unique<Impl>(std::move(config))) {}
ModbusChamber::~ModbusChamber() = default;

std::string ModbusChamber::describe() const { return impl_->who(); }

std::uint64_t ModbusChamber::reconnects() const {
  std::lock_guard lock(impl_->mutex);
  return impl_->link.reconnects();
}

DeviceState ModbusChamber::state() const {
  std::lock_guard lock(impl_->mutex);
  if (impl_->state != DeviceState::disconnected && !impl_->link.is_open()) return DeviceState::faulted;
  return impl_->state;
}

Result<void> ModbusChamber::connect() {
  std::lock_guard lock(impl_->mutex);
  if (auto r = impl_->link.open(true); !r) return r.error();
  // A request proves the controller answers (a TCP connect alone may reach a gateway only).
  auto unit = impl_->read_unit();
  if (!unit) return unit.error();
  impl_->state = DeviceState::connected;
  return success();
}

Result<void> ModbusChamber::configure() {
  std::lock_guard lock(impl_->mutex);
  if (impl_->state == DeviceState::disconnected) return {DriverErrc::invalid_state, impl_->who() + ": configure before connect"};
  // Every mapped register must answer: a wrong map is found here, not in the middle of a run.
  auto unit = impl_->read_unit();
  if (!unit) return unit.error();
  if (auto r = impl_->read_temperature(impl_->cfg.map.process_value, *unit, "reading the process value"); !r) return r.error();
  if (auto r = impl_->read_regs(impl_->cfg.map.setpoint, impl_->cfg.map.registers_per_value(), "reading the set point"); !r) return r.error();
  const RegisterMap& map = impl_->cfg.map;
  if (const auto& ws = map.working_setpoint)
    if (auto r = impl_->read_regs(*ws, map.registers_per_value(), "reading the working set point"); !r) return r.error();
  if (const auto& cm = map.control_mode)
    if (auto r = impl_->read_regs(cm->address, 1, "reading the control mode"); !r) return r.error();
  if (auto r = impl_->read_alarms(); !r) return r.error();
  impl_->state = DeviceState::configured;
  return success();
}

Result<void> ModbusChamber::activate() {
  std::lock_guard lock(impl_->mutex);
  if (impl_->state != DeviceState::configured && impl_->state != DeviceState::active)
    return {DriverErrc::invalid_state, impl_->who() + ": activate before configure"};
  auto alarms = impl_->read_alarms();
  if (!alarms) return alarms.error();
  if (!alarms->empty()) return {DriverErrc::alarm, impl_->who() + ": will not activate with alarm '" + (*alarms)[0].name + "' active"};
  if (auto r = impl_->set_control(true); !r) return r;
  impl_->state = DeviceState::active;
  return success();
}

Result<void> ModbusChamber::safe_stop() {
  std::lock_guard lock(impl_->mutex);
  impl_->ramp.reset();
  impl_->device_ramp_target_C.reset();
  if (impl_->state == DeviceState::disconnected) return success();
  Result<void> r;
  if (const auto safe_C = impl_->cfg.safe_setpoint_C) {
    auto unit = impl_->read_unit();
    if (!unit) return unit.error();
    if (auto w = impl_->write_device_ramp_rate(0.0, *unit); !w) return w;
    r = impl_->write_temperature(impl_->cfg.map.setpoint, *safe_C, *unit, "writing the safe set point");
  } else {
    r = impl_->set_control(false);
  }
  if (r) impl_->state = DeviceState::configured;
  return r;
}

void ModbusChamber::disconnect() noexcept {
  std::lock_guard lock(impl_->mutex);
  impl_->link.close();
  impl_->ramp.reset();
  impl_->state = DeviceState::disconnected;
}

Result<void> ModbusChamber::set_setpoint(double setpoint_C) {
  std::lock_guard lock(impl_->mutex);
  if (impl_->state == DeviceState::disconnected) return {DriverErrc::invalid_state, impl_->who() + ": not connected"};
  if (auto r = impl_->check_setpoint(setpoint_C); !r) return r;
  impl_->ramp.reset();
  impl_->device_ramp_target_C.reset();
  auto unit = impl_->read_unit();
  if (!unit) return unit.error();
  // A ramp-rate register left non-zero would make the controller ramp to this set point.
  if (auto r = impl_->write_device_ramp_rate(0.0, *unit); !r) return r;
  return impl_->write_temperature(impl_->cfg.map.setpoint, setpoint_C, *unit, "writing the set point");
}

Result<void> ModbusChamber::ramp_to(double target_C, double rate_C_per_min) {
  std::lock_guard lock(impl_->mutex);
  Impl& m = *impl_;
  if (m.state == DeviceState::disconnected) return {DriverErrc::invalid_state, m.who() + ": not connected"};
  if (auto r = m.check_setpoint(target_C); !r) return r;
  if (!std::isfinite(rate_C_per_min) || !(rate_C_per_min > 0.0))
    return {DriverErrc::invalid_argument, m.who() + ": ramp rate must be a positive number of C/min"};
  auto unit = m.read_unit();
  if (!unit) return unit.error();
  m.ramp.reset();
  m.device_ramp_target_C.reset();
  if (m.cfg.map.ramp_rate_per_min) {
    if (auto r = m.write_device_ramp_rate(rate_C_per_min, *unit); !r) return r;
    if (auto r = m.write_temperature(m.cfg.map.setpoint, target_C, *unit, "writing the ramp target"); !r) return r;
    m.device_ramp_target_C = target_C;
    return success();
  }
  // Driver ramp: start from the set point the controller holds now.
  auto sp = m.read_temperature(m.cfg.map.setpoint, *unit, "reading the set point");
  if (!sp) return sp.error();
  m.ramp = Impl::Ramp{*sp, target_C, rate_C_per_min / 60.0, Clock::now(), *sp};
  return success();
}

Result<ChamberReading> ModbusChamber::read() {
  std::lock_guard lock(impl_->mutex);
  Impl& m = *impl_;
  if (m.state == DeviceState::disconnected) return {DriverErrc::invalid_state, m.who() + ": not connected"};
  ChamberReading out;
  auto unit = m.read_unit();
  if (!unit) return unit.error();
  out.device_unit = *unit;

  // Driver ramp: one step per read, on the controller before the values are read back.
  if (m.ramp) {
    const double elapsed_s = std::chrono::duration<double>(Clock::now() - m.ramp->start).count();
    const double dir = m.ramp->target_C >= m.ramp->start_C ? 1.0 : -1.0;
    double sp = m.ramp->start_C + dir * m.ramp->rate_C_per_s * elapsed_s;
    const bool done = dir > 0 ? sp >= m.ramp->target_C : sp <= m.ramp->target_C;
    if (done) sp = m.ramp->target_C;
    if (done || std::fabs(sp - m.ramp->last_written_C) >= m.resolution_C()) {
      if (auto r = m.write_temperature(m.cfg.map.setpoint, sp, *unit, "writing a ramp step"); !r) return r.error();
      m.ramp->last_written_C = sp;
    }
    if (done) m.ramp.reset();
  }

  const std::int64_t t0 = host_time_ns();
  auto pv = m.read_temperature(m.cfg.map.process_value, *unit, "reading the process value");
  if (!pv) return pv.error();
  out.t_ns = t0 + (host_time_ns() - t0) / 2;
  out.process_C = *pv;
  auto sp = m.read_temperature(m.cfg.map.setpoint, *unit, "reading the set point");
  if (!sp) return sp.error();
  out.setpoint_C = *sp;
  if (m.cfg.map.working_setpoint) {
    auto wsp = m.read_temperature(*m.cfg.map.working_setpoint, *unit, "reading the working set point");
    if (!wsp) return wsp.error();
    out.working_setpoint_C = *wsp;
    if (m.device_ramp_target_C && std::fabs(*wsp - *m.device_ramp_target_C) < m.resolution_C())
      m.device_ramp_target_C.reset();
  }
  if (m.ramp) out.ramp_target_C = m.ramp->target_C;
  else if (m.device_ramp_target_C) out.ramp_target_C = m.device_ramp_target_C;
  auto alarms = m.read_alarms();
  if (!alarms) return alarms.error();
  out.alarms = std::move(*alarms);
  return out;
}

Result<void> ModbusChamber::check_alarms() {
  std::lock_guard lock(impl_->mutex);
  if (impl_->state == DeviceState::disconnected) return {DriverErrc::invalid_state, impl_->who() + ": not connected"};
  auto alarms = impl_->read_alarms();
  if (!alarms) return alarms.error();
  if (alarms->empty()) return success();
  std::string names;
  for (const ChamberAlarm& a : *alarms) names += (names.empty() ? "" : ", ") + a.name + " (" + std::to_string(a.raw) + ")";
  return {DriverErrc::alarm, impl_->who() + ": alarm active: " + names};
}

}  // namespace imucal::drivers
