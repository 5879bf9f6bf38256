// The Modbus register map of a chamber controller, as configuration: which holding registers hold
// the process value, the set point, the ramping (working) set point, a ramp rate, the control
// mode, the temperature unit and the alarms, and how a temperature is encoded in them. JSON form
// "imucal-chamber-map/1" (docs/drivers.md); the built-in maps are the files of
// drivers/chamber_maps/, each saying which manual it was checked against (`source`). The same map drives the Modbus driver and the simulated chamber.
#pragma once

#include <cstdint>
#include <optional>
#include <span>
#include <string>
#include <utility>
#include <vector>

#include "drivers/interfaces.hpp"
#include "drivers/word_order.hpp"

namespace imucal::drivers {

enum class ValueEncoding {
  float32,     // IEEE-754 binary32 over two registers, in the map's word order
  scaled_i16,  // one signed 16-bit register holding value * scale
};

struct AlarmRegister {
  std::string name;
  int address = 0;
  // Active when (value & mask) != 0 (mask non-zero), or when the value is not one of `normal`
  // (enumerated alarm states). One of the two is given.
  std::uint16_t mask = 0;
  std::vector<std::uint16_t> normal;

  bool active(std::uint16_t value) const noexcept;
};

struct ControlModeRegister {
  int address = 0;
  std::uint16_t auto_value = 0;  // closed-loop control on
  std::uint16_t off_value = 0;   // control off
};

struct UnitsRegister {
  int address = 0;
  std::uint16_t celsius_value = 0;
  std::uint16_t fahrenheit_value = 0;
};

// Where a map's addresses come from: the maker's manual each was checked against, with the page,
// or that it was not (then it must be checked on the controller at hand).
struct RegisterSource {
  std::string key;  // the map's key: value, process_value, setpoint, ..., alarms
  bool checked = false;
  std::string where;  // the manual's page and what it says, or why it is not checked
};

struct MapSource {
  std::string manual;    // title
  std::string document;  // number, revision, date
  std::vector<RegisterSource> registers;  // every key the map uses (absent from the file: not checked)
  std::string note;

  bool fully_checked() const noexcept;
  std::vector<std::string> unchecked_keys() const;
  // "checked against <manual> (<document>)", "partly checked against <manual> (<document>); not
  // checked: control_mode, alarms", or "not checked against a maker's manual".
  std::string summary() const;
};

struct RegisterMap {
  std::string name;
  MapSource source;
  int slave_id = 1;
  ValueEncoding encoding = ValueEncoding::float32;
  words::WordOrder word_order = words::WordOrder::high_word_first;
  double scale = 10.0;  // scaled_i16 only
  int process_value = 0;
  int setpoint = 0;
  std::optional<int> working_setpoint;   // read-only: the set point the loop follows while ramping
  std::optional<int> ramp_rate_per_min;  // device ramp rate, temperature units per minute
  std::optional<ControlModeRegister> control_mode;
  std::optional<UnitsRegister> units;
  TemperatureUnit fixed_unit = TemperatureUnit::celsius;  // when there is no units register
  std::vector<AlarmRegister> alarms;
  // A process value outside this range (Celsius) is treated as a corrupted reply.
  double plausible_min_C = -150.0;
  double plausible_max_C = 400.0;

  int registers_per_value() const noexcept { return encoding == ValueEncoding::float32 ? 2 : 1; }
  // Highest register address used plus one (sizes the simulated chamber's register bank).
  int address_end() const noexcept;
};

// Parses imucal-chamber-map/1. Throws std::invalid_argument naming the key at fault.
RegisterMap register_map_from_json(const std::string& json_text);
// A built-in name ("watlow-f4t", "csz-ezt570i") or a path to a JSON file.
RegisterMap load_register_map(const std::string& name_or_path);
std::vector<std::string> builtin_register_map_names();
std::string builtin_register_map_json(const std::string& name);  // throws for an unknown name

// A temperature (in the device's unit) as the registers that hold it; empty when it cannot be
// represented (not finite, outside int16 after scaling).
std::optional<std::vector<std::uint16_t>> encode_value(const RegisterMap& map, double value);
// The registers of one value back to a number; empty when they do not hold a finite number or
// the span has the wrong length. Plausibility is the caller's (it knows the unit).
std::optional<double> decode_value(const RegisterMap& map, std::span<const std::uint16_t> regs);

double celsius_to_unit(double celsius, TemperatureUnit unit) noexcept;
double unit_to_celsius(double value, TemperatureUnit unit) noexcept;
// A temperature difference or rate (no offset).
double celsius_delta_to_unit(double delta_C, TemperatureUnit unit) noexcept;

}  // namespace imucal::drivers
