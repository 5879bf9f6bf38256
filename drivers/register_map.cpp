#include "drivers/register_map.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>

#include <nlohmann/json.hpp>

#include "core/json_reader.hpp"
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

// A register address, or nothing when the key is absent or null (null: "this controller has none").
std::optional<int> address(ObjectReader& r, const char* key, bool required = false) {
  const json* v = r.get(key, required);
  if (v == nullptr || v->is_null()) return std::nullopt;
  return static_cast<int>(r.required_integer(key, 0, 65535));
}

// A register address the map must have: absent or null is refused.
int required_address(ObjectReader& r, const char* key) {
  if (const auto a = address(r, key, true)) return *a;
  r.fail(r.at(key), "is required: a register address (0-65535), not null");
}

std::uint16_t word(ObjectReader& r, const char* key) { return static_cast<std::uint16_t>(r.required_integer(key, 0, 65535)); }

// The object under `key` (absent or null: nullptr); anything else than an object is refused.
const json* object_or_null(ObjectReader& r, const char* key) {
  const json* v = r.get(key);
  if (v == nullptr || v->is_null()) return nullptr;
  if (!v->is_object()) r.fail(r.at(key), "must be an object, not " + json_type_name(*v));
  return v;
}

const json& array_at(ObjectReader& r, const char* key) {
  const json* v = r.get(key, true);
  if (!v->is_array()) r.fail(r.at(key), "must be an array, not " + json_type_name(*v));
  return *v;
}

// The keys of `j` that carry addresses or encodings, in the order the map format lists them.
std::vector<std::string> used_keys(const json& j) {
  std::vector<std::string> keys;
  for (const char* k : {"value", "process_value", "setpoint", "working_setpoint", "ramp_rate_per_min", "control_mode",
                        "units", "fixed_unit", "alarms"})
    if (j.contains(k) && !j[k].is_null() && !(j[k].is_array() && j[k].empty())) keys.emplace_back(k);
  return keys;
}

void read_value(ObjectReader& r, RegisterMap& m) {
  const std::string type = r.required_string("type");
  if (type == "float32") {
    m.encoding = ValueEncoding::float32;
    const std::string order = r.required_string("word_order");
    try {
      m.word_order = words::word_order_from_string(order);
    } catch (const std::invalid_argument& e) {
      r.fail(r.at("word_order"), e.what());
    }
  } else if (type == "int16") {
    m.encoding = ValueEncoding::scaled_i16;
    m.scale = r.required_number("scale");
    if (!(m.scale > 0.0)) r.fail(r.at("scale"), "must be a positive number");
  } else {
    r.fail(r.at("type"), "is \"" + type + "\", must be \"float32\" or \"int16\"");
  }
  r.finish();
}

AlarmRegister read_alarm(ObjectReader& r) {
  AlarmRegister a;
  a.name = r.required_string("name");
  a.address = required_address(r, "address");
  if (r.has("mask")) a.mask = word(r, "mask");
  if (r.has("normal")) {
    const json& normal = array_at(r, "normal");
    for (std::size_t i = 0; i < normal.size(); ++i) {
      const json& n = normal[i];
      if (!n.is_number_integer() || n.get<long long>() < 0 || n.get<long long>() > 65535)
        r.fail(r.at("normal") + "[" + std::to_string(i) + "]", "must be an integer between 0 and 65535");
      a.normal.push_back(static_cast<std::uint16_t>(n.get<int>()));
    }
  }
  if ((a.mask == 0) == a.normal.empty())
    r.fail(r.where(), "alarm '" + a.name + "' needs exactly one of 'mask' (non-zero) or 'normal'");
  r.finish();
  return a;
}

// `source`: {"manual", "document", "registers": {key: {"checked", "where"}}, "note"}. Every key
// the map uses is listed; one the source does not name is "not checked".
MapSource read_source(const json* src, const std::vector<std::string>& used, const ObjectReader::ThrowAtFirst& mode) {
  MapSource s;
  std::optional<ObjectReader> r;
  const json* regs = nullptr;
  if (src != nullptr) {
    r.emplace(*src, "source", mode);
    s.manual = r->string("manual").value_or("");
    s.document = r->string("document").value_or("");
    s.note = r->string("note").value_or("");
    regs = object_or_null(*r, "registers");
    r->finish();
  }
  if (r && regs != nullptr)  // regs is read from r
    for (const auto& [key, entry] : regs->items())
      if (std::find(used.begin(), used.end(), key) == used.end())
        r->fail("'source.registers." + key + "' is not a key the map uses");
  for (const std::string& key : used) {
    RegisterSource reg;
    reg.key = key;
    if (regs != nullptr && regs->contains(key)) {
      ObjectReader e((*regs)[key], "source.registers." + key, mode);
      reg.checked = e.boolean("checked").value_or(false);
      reg.where = e.string("where").value_or("");
      e.finish();
      if (reg.checked && s.manual.empty()) e.fail("'" + e.where() + "' is checked but the source names no manual");
    } else {
      reg.where = "not named in the map's source";
    }
    s.registers.push_back(std::move(reg));
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
  // Messages name the map when it has a name: "register map 'x': process_value is 70000, ...".
  const std::string name = j.is_object() && j.contains("name") && j["name"].is_string() ? j["name"].get<std::string>() : "";
  const ObjectReader::ThrowAtFirst mode{"register map" + (name.empty() ? std::string() : " '" + name + "'") + ": "};
  ObjectReader r(j, "", mode);
  if (r.string("format").value_or("") != "imucal-chamber-map/1") r.fail("format", "must be \"imucal-chamber-map/1\"");
  RegisterMap m;
  m.name = r.string("name").value_or("custom");
  m.slave_id = static_cast<int>(r.integer("slave_id", 0, 247).value_or(1));
  {
    ObjectReader value(r.required("value"), "value", mode);
    read_value(value, m);
  }
  m.process_value = required_address(r, "process_value");
  m.setpoint = required_address(r, "setpoint");
  m.working_setpoint = address(r, "working_setpoint");
  m.ramp_rate_per_min = address(r, "ramp_rate_per_min");
  if (const json* c = object_or_null(r, "control_mode")) {
    ObjectReader cr(*c, "control_mode", mode);
    m.control_mode = ControlModeRegister{required_address(cr, "address"), word(cr, "auto"), word(cr, "off")};
    cr.finish();
  }
  if (const json* u = object_or_null(r, "units")) {
    ObjectReader ur(*u, "units", mode);
    m.units = UnitsRegister{required_address(ur, "address"), word(ur, "C"), word(ur, "F")};
    ur.finish();
    if (m.units->celsius_value == m.units->fahrenheit_value) ur.fail("units.C and units.F must differ");
  }
  if (const auto unit = r.string("fixed_unit")) {
    if (*unit == "C") m.fixed_unit = TemperatureUnit::celsius;
    else if (*unit == "F") m.fixed_unit = TemperatureUnit::fahrenheit;
    else r.fail("fixed_unit", "is \"" + *unit + "\", must be \"C\" or \"F\"");
  }
  if (r.has("alarms")) {
    const json& alarms = array_at(r, "alarms");
    for (std::size_t i = 0; i < alarms.size(); ++i) {
      ObjectReader ar(alarms[i], "alarms[" + std::to_string(i) + "]", mode);
      m.alarms.push_back(read_alarm(ar));
    }
  }
  if (r.has("plausible_range_C")) {
    const json& range = r.required("plausible_range_C");
    if (!range.is_array() || range.size() != 2 || !range[0].is_number() || !range[1].is_number() ||
        !(range[0].get<double>() < range[1].get<double>()))
      r.fail("plausible_range_C", "must be [min, max] in Celsius with min < max");
    m.plausible_min_C = range[0].get<double>();
    m.plausible_max_C = range[1].get<double>();
  }
  m.source = read_source(object_or_null(r, "source"), used_keys(j), mode);
  r.finish();
  return m;
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
