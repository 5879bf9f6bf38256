#include "drivers/power_relay.hpp"

#include <cerrno>
#include <mutex>
#include <stdexcept>

#include <modbus/modbus.h>
#include <nlohmann/json.hpp>

#include "core/json_reader.hpp"

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
  PowerRelayConfig c;
  ObjectReader r(j, "", ObjectReader::ThrowAtFirst{pre});
  if (const auto f = r.string("format"); f && *f != "imucal-power-relay/1")
    r.fail(r.at("format") + " must be \"imucal-power-relay/1\"");
  read_modbus_link(r, c);
  if (const auto v = r.integer("unit_id", 1, 247)) c.unit_id = static_cast<int>(*v);
  if (const auto v = r.integer("coil", 0, 65535)) c.coil = static_cast<int>(*v);
  c.on_when_set = r.boolean("on_when_set").value_or(c.on_when_set);
  // Long enough for the supply's capacitors to drain and the IMU to boot afresh; short enough
  // that a typo does not leave the unit off for hours.
  if (const auto v = r.number_in("off_s", 1.0, 600.0)) c.off_s = *v;
  r.finish();
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
