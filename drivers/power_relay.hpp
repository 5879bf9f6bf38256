// The IMU's supply switched through one coil of a Modbus device: a relay module, or a digital
// output of the chamber controller wired to a contactor. Used by the daemon's power-cycle
// segments (turn-on to turn-on repeatability) so that an overnight run needs nobody at the
// bench. Each switch is written and read back; a coil that does not read back as written is an
// error naming the coil. Thread-safe: calls are serialised by an internal mutex.
#pragma once

#include <memory>
#include <string>

#include "drivers/interfaces.hpp"
#include "drivers/modbus_link.hpp"

namespace imucal::drivers {

struct PowerRelayConfig : ModbusLinkConfig {
  int unit_id = 1;           // the Modbus unit (slave) address
  int coil = 0;              // coil address as on the wire (0-based)
  bool on_when_set = true;   // false: a normally-closed contact powers the IMU while the coil is clear
  double off_s = 10.0;       // how long a power cycle leaves the IMU unpowered
};

// "imucal-power-relay/1" JSON: the link keys of read_modbus_link, "unit_id" (1..247), "coil"
// (0..65535), "on_when_set" (bool), "off_s" (1..600). Throws std::invalid_argument
// "power relay config: '<key>' ...".
PowerRelayConfig power_relay_config_from_json(const std::string& json_text);

class PowerRelay {
 public:
  explicit PowerRelay(PowerRelayConfig config);
  ~PowerRelay();
  PowerRelay(const PowerRelay&) = delete;
  PowerRelay& operator=(const PowerRelay&) = delete;

  // Switches the IMU's supply and reads the coil back.
  Result<void> set_power(bool on);
  // Whether the coil says the IMU is powered.
  Result<bool> powered();
  const PowerRelayConfig& config() const noexcept;
  // "power relay modbus-tcp://host:502 unit 1 coil 3".
  std::string describe() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace imucal::drivers
