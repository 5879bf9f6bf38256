#include "drivers/power_relay.hpp"

#include <cerrno>
#include <cmath>
#include <mutex>
#include <stdexcept>

#include <modbus/modbus.h>
#include <nlohmann/json.hpp>

namespace imucal::drivers {

PowerRelayConfig power_relay_config_from_json(const std::string& json_text) {
  using nlohmann::json;
  const std::string pre = "power relay config: ";
  json j;
  try {
    j = json::parse(json_text);
  } catch (const json::exception& e) {
    throw std::invalid_argument(pre + "not valid JSON: " + e.what());
  }
  if (!j.is_object()) throw std::invalid_argument(pre + "must be an object");
  PowerRelayConfig c;
  try {
    read_modbus_link(j, "power relay", c);
    c.unit_id = j.value("unit_id", c.unit_id);
    if (c.unit_id < 1 || c.unit_id > 247) throw std::invalid_argument(pre + "'unit_id' must be 1..247");
    c.coil = j.value("coil", c.coil);
    if (c.coil < 0 || c.coil > 65535) throw std::invalid_argument(pre + "'coil' must be 0..65535");
    c.on_when_set = j.value("on_when_set", c.on_when_set);
    c.off_s = j.value("off_s", c.off_s);
    // Long enough for the supply's capacitors to drain and the IMU to boot afresh; short
    // enough that a typo does not leave the unit off for hours.
    if (!std::isfinite(c.off_s) || c.off_s < 1.0 || c.off_s > 600.0)
      throw std::invalid_argument(pre + "'off_s' must be 1..600 seconds");
  } catch (const json::exception& e) {
    throw std::invalid_argument(pre + e.what());
  }
  return c;
}

struct PowerRelay::Impl {
  PowerRelayConfig cfg;
  std::mutex mutex;
  ModbusLink link;
  explicit Impl(PowerRelayConfig c)
      : cfg(std::move(c)),
        link(cfg, cfg.unit_id,
             "power relay " + cfg.address() + " unit " + std::to_string(cfg.unit_id) + " coil " + std::to_string(cfg.coil)) {}

  Result<bool> read_coil() {
    auto ctx = link.open(false);
    if (!ctx) return ctx.error();
    std::uint8_t bit = 0;
    errno = 0;
    if (modbus_read_bits(*ctx, cfg.coil, 1, &bit) != 1) {
      if (errno == 0) errno = EMBBADDATA;
      return link.fail("reading the coil");
    }
    return bit != 0;
  }
};

PowerRelay::PowerRelay(PowerRelayConfig config) : impl_(std::make_unique<Impl>(std::move(config))) {}
PowerRelay::~PowerRelay() = default;

const PowerRelayConfig& PowerRelay::config() const noexcept { return impl_->cfg; }
std::string PowerRelay::describe() const { return impl_->link.who(); }

Result<void> PowerRelay::set_power(bool on) {
  std::lock_guard lock(impl_->mutex);
  Impl& m = *impl_;
  const bool coil_value = on == m.cfg.on_when_set;
  auto ctx = m.link.open(false);
  if (!ctx) return ctx.error();
  errno = 0;
  if (modbus_write_bit(*ctx, m.cfg.coil, coil_value ? 1 : 0) != 1) {
    if (errno == 0) errno = EMBBADDATA;
    return m.link.fail(std::string("switching the IMU ") + (on ? "on" : "off"));
  }
  auto back = m.read_coil();
  if (!back) return back.error();
  if (*back != coil_value)
    return {DriverErrc::device_rejected, m.link.who() + ": the coil reads " + (*back ? "set" : "clear") +
                                             " after it was written " + (coil_value ? "set" : "clear") +
                                             " (is the coil address right, or the output forced locally?)"};
  return success();
}

Result<bool> PowerRelay::powered() {
  std::lock_guard lock(impl_->mutex);
  auto bit = impl_->read_coil();
  if (!bit) return bit.error();
  return *bit == impl_->cfg.on_when_set;
}

}  // namespace imucal::drivers
