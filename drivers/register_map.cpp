#include "drivers/register_map.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>

#include <nlohmann/json.hpp>

#include "drivers/chamber_maps_builtin.hpp"  // generated from drivers/chamber_maps/*.json

namespace imucal::drivers {

using nlohmann::json;

bool AlarmRegister::active(std::uint16_t value) const noexcept {
  if (mask != 0) return (value & mask) != 0;
  return std::find(normal.begin(), normal.end(), value) == normal.end();
}

int RegisterMap::address_end() const noexcept {
  int end = std::max(process_value, setpoint) + registers_per_value();
  auto upd = [&](int a, int n) { end = std::max(end, a + n); };
  if (working_setpoint) upd(*working_setpoint, registers_per_value());
  if (ramp_rate_per_min) upd(*ramp_rate_per_min, registers_per_value());
  if (control_mode) upd(control_mode->address, 1);
  if (units) upd(units->address, 1);
  for (const AlarmRegister& a : alarms) upd(a.address, 1);
  return end;
}

namespace {

int get_address(const json& j, const char* key) {
  const json& v = j.at(key);
  if (!v.is_number_integer() || v.get<long long>() < 0 || v.get<long long>() > 65535)
    throw std::invalid_argument(std::string("register map: '") + key +
                                "' must be a register address 0..65535");
  return v.get<int>();
}

std::uint16_t get_u16(const json& j, const char* key, const char* where) {
  const json& v = j.at(key);
  if (!v.is_number_integer() || v.get<long long>() < 0 || v.get<long long>() > 65535)
    throw std::invalid_argument(std::string("register map: '") + where + "." + key +
                                "' must be an integer 0..65535");
  return static_cast<std::uint16_t>(v.get<int>());
}

TemperatureUnit parse_unit(const std::string& s) {
  if (s == "C") return TemperatureUnit::celsius;
  if (s == "F") return TemperatureUnit::fahrenheit;
  throw std::invalid_argument("register map: 'fixed_unit' must be \"C\" or \"F\"");
}

// The keys of `j` that carry addresses or encodings, in the order the map format lists them.
std::vector<std::string> used_keys(const json& j) {
  std::vector<std::string> keys;
  for (const char* k : {"value", "process_value", "setpoint", "working_setpoint", "ramp_rate_per_min", "control_mode",
                        "units", "fixed_unit", "alarms"})
    if (j.contains(k) && !j[k].is_null() && !(j[k].is_array() && j[k].empty())) keys.emplace_back(k);
  return keys;
}

// `source`: {"manual", "document", "registers": {key: {"checked", "where"}}, "note"}. Every key
// the map uses is listed; one the source does not name is "not checked".
MapSource read_source(const json& j, const RegisterMap& m) {
  MapSource s;
  const json* src = j.contains("source") ? &j["source"] : nullptr;
  if (src && !src->is_object()) throw std::invalid_argument("register map: 'source' must be an object");
  if (src) {
    s.manual = src->value("manual", std::string());
    s.document = src->value("document", std::string());
    s.note = src->value("note", std::string());
  }
  const json* regs = src && src->contains("registers") ? &(*src)["registers"] : nullptr;
  if (regs && !regs->is_object()) throw std::invalid_argument("register map: 'source.registers' must be an object");
  const std::vector<std::string> keys = used_keys(j);
  if (regs)
    for (const auto& [key, entry] : regs->items())
      if (std::find(keys.begin(), keys.end(), key) == keys.end())
        throw std::invalid_argument("register map '" + m.name + "': 'source.registers." + key + "' is not a key the map uses");
  for (const std::string& key : keys) {
    RegisterSource r;
    r.key = key;
    if (regs && regs->contains(key)) {
      const json& e = (*regs)[key];
      r.checked = e.value("checked", false);
      r.where = e.value("where", std::string());
    } else {
      r.where = "not named in the map's source";
    }
    if (r.checked && s.manual.empty())
      throw std::invalid_argument("register map '" + m.name + "': 'source.registers." + key + "' is checked but the source names no manual");
    s.registers.push_back(std::move(r));
  }
  return s;
}

}  // namespace

RegisterMap register_map_from_json(const std::string& json_text) {
  json j;
  try {
    j = json::parse(json_text);
  } catch (const json::exception& e) {
    throw std::invalid_argument(std::string("register map: not valid JSON: ") + e.what());
  }
  try {
    if (j.value("format", std::string()) != "imucal-chamber-map/1")
      throw std::invalid_argument("register map: 'format' must be \"imucal-chamber-map/1\"");
    RegisterMap m;
    m.name = j.value("name", std::string("custom"));
    m.slave_id = j.value("slave_id", 1);
    if (m.slave_id < 0 || m.slave_id > 247)
      throw std::invalid_argument("register map: 'slave_id' must be 0..247");
    const json& v = j.at("value");
    const std::string type = v.at("type").get<std::string>();
    if (type == "float32") {
      m.encoding = ValueEncoding::float32;
      m.word_order = words::word_order_from_string(v.at("word_order").get<std::string>());
    } else if (type == "int16") {
      m.encoding = ValueEncoding::scaled_i16;
      m.scale = v.at("scale").get<double>();
      if (!(m.scale > 0.0) || !std::isfinite(m.scale))
        throw std::invalid_argument("register map: 'value.scale' must be a positive number");
    } else {
      throw std::invalid_argument("register map: 'value.type' must be \"float32\" or \"int16\"");
    }
    m.process_value = get_address(j, "process_value");
    m.setpoint = get_address(j, "setpoint");
    if (j.contains("working_setpoint") && !j["working_setpoint"].is_null())
      m.working_setpoint = get_address(j, "working_setpoint");
    if (j.contains("ramp_rate_per_min") && !j["ramp_rate_per_min"].is_null())
      m.ramp_rate_per_min = get_address(j, "ramp_rate_per_min");
    if (j.contains("control_mode") && !j["control_mode"].is_null()) {
      const json& c = j["control_mode"];
      m.control_mode = ControlModeRegister{get_address(c, "address"), get_u16(c, "auto", "control_mode"),
                                           get_u16(c, "off", "control_mode")};
    }
    if (j.contains("units") && !j["units"].is_null()) {
      const json& u = j["units"];
      m.units = UnitsRegister{get_address(u, "address"), get_u16(u, "C", "units"), get_u16(u, "F", "units")};
      if (m.units->celsius_value == m.units->fahrenheit_value)
        throw std::invalid_argument("register map: 'units.C' and 'units.F' must differ");
    }
    if (j.contains("fixed_unit")) m.fixed_unit = parse_unit(j["fixed_unit"].get<std::string>());
    if (j.contains("alarms")) {
      for (const json& a : j.at("alarms")) {
        AlarmRegister r;
        r.name = a.at("name").get<std::string>();
        r.address = get_address(a, "address");
        if (a.contains("mask")) r.mask = get_u16(a, "mask", "alarms[]");
        if (a.contains("normal"))
          for (const json& n : a["normal"]) {
            if (!n.is_number_integer() || n.get<long long>() < 0 || n.get<long long>() > 65535)
              throw std::invalid_argument("register map: 'alarms[].normal' holds integers 0..65535");
            r.normal.push_back(static_cast<std::uint16_t>(n.get<int>()));
          }
        if ((r.mask == 0) == r.normal.empty())
          throw std::invalid_argument("register map: alarm '" + r.name +
                                      "' needs exactly one of 'mask' (non-zero) or 'normal'");
        m.alarms.push_back(std::move(r));
      }
    }
    if (j.contains("plausible_range_C")) {
      const auto r = j["plausible_range_C"].get<std::vector<double>>();
      if (r.size() != 2 || !(r[0] < r[1]))
        throw std::invalid_argument("register map: 'plausible_range_C' must be [min, max]");
      m.plausible_min_C = r[0];
      m.plausible_max_C = r[1];
    }
    m.source = read_source(j, m);
    return m;
  } catch (const json::exception& e) {
    throw std::invalid_argument(std::string("register map '") + j.value("name", std::string("?")) +
                                "': " + e.what());
  }
}

std::vector<std::string> builtin_register_map_names() { return embedded_names(builtin::kChamberMaps); }

std::string builtin_register_map_json(const std::string& name) {
  return embedded_text(builtin::kChamberMaps, name, "register map");
}

bool MapSource::fully_checked() const noexcept {
  return !registers.empty() && std::all_of(registers.begin(), registers.end(), [](const RegisterSource& r) { return r.checked; });
}

std::vector<std::string> MapSource::unchecked_keys() const {
  std::vector<std::string> keys;
  for (const RegisterSource& r : registers)
    if (!r.checked) keys.push_back(r.key);
  return keys;
}

std::string MapSource::summary() const {
  const std::vector<std::string> unchecked = unchecked_keys();
  if (unchecked.size() == registers.size()) return "not checked against a maker's manual";
  std::string s = (unchecked.empty() ? "checked against " : "partly checked against ") + manual;
  if (unchecked.empty()) return s;
  s += "; not checked: ";
  for (std::size_t i = 0; i < unchecked.size(); ++i) s += (i ? ", " : "") + unchecked[i];
  return s;
}

RegisterMap load_register_map(const std::string& name_or_path) {
  return register_map_from_json(embedded_or_file_text(builtin::kChamberMaps, name_or_path, "register map"));
}

std::optional<std::vector<std::uint16_t>> encode_value(const RegisterMap& map, double value) {
  if (!std::isfinite(value)) return std::nullopt;
  if (map.encoding == ValueEncoding::float32) {
    if (std::fabs(value) > static_cast<double>(std::numeric_limits<float>::max())) return std::nullopt;
    const auto w = words::pack_float32(static_cast<float>(value), map.word_order);
    return std::vector<std::uint16_t>{w[0], w[1]};
  }
  const auto r = words::pack_scaled_i16(value, map.scale);
  if (!r) return std::nullopt;
  return std::vector<std::uint16_t>{*r};
}

std::optional<double> decode_value(const RegisterMap& map, std::span<const std::uint16_t> regs) {
  if (static_cast<int>(regs.size()) != map.registers_per_value()) return std::nullopt;
  double v = 0.0;
  if (map.encoding == ValueEncoding::float32)
    v = static_cast<double>(words::unpack_float32(regs[0], regs[1], map.word_order));
  else
    v = words::unpack_scaled_i16(regs[0], map.scale);
  if (!std::isfinite(v)) return std::nullopt;
  return v;
}

double celsius_to_unit(double celsius, TemperatureUnit unit) noexcept {
  return unit == TemperatureUnit::fahrenheit ? celsius * 9.0 / 5.0 + 32.0 : celsius;
}

double unit_to_celsius(double value, TemperatureUnit unit) noexcept {
  return unit == TemperatureUnit::fahrenheit ? (value - 32.0) * 5.0 / 9.0 : value;
}

double celsius_delta_to_unit(double delta_C, TemperatureUnit unit) noexcept {
  return unit == TemperatureUnit::fahrenheit ? delta_C * 9.0 / 5.0 : delta_C;
}

}  // namespace imucal::drivers
