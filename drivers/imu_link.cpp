#include "drivers/imu_link.hpp"

#include "core/json_reader.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <set>
#include <stdexcept>
#include <utility>

#include <nlohmann/json.hpp>

#include "core/json_reader.hpp"
#include "drivers/imu_links_builtin.hpp"

namespace imucal::drivers::link {

using nlohmann::json;

namespace {

constexpr double kStandardGravity_mps2 = 9.80665;  // the "g" of accelerometer data sheets
constexpr double kPi = 3.14159265358979323846;
constexpr double kFoot_m = 0.3048;

struct NamedType {
  const char* name;
  FieldType type;
};
constexpr std::array<NamedType, 11> kTypes = {{{"uint8", FieldType::u8},   {"int8", FieldType::i8},
                                               {"uint16", FieldType::u16}, {"int16", FieldType::i16},
                                               {"uint32", FieldType::u32}, {"int32", FieldType::i32},
                                               {"uint64", FieldType::u64}, {"int64", FieldType::i64},
                                               {"float32", FieldType::f32}, {"float64", FieldType::f64},
                                               {"ascii", FieldType::ascii}}};

struct NamedRole {
  const char* name;
  Role role;
};
constexpr std::array<NamedRole, 16> kRoles = {{{"gyro_x", Role::gyro_x},
                                               {"gyro_y", Role::gyro_y},
                                               {"gyro_z", Role::gyro_z},
                                               {"accel_x", Role::accel_x},
                                               {"accel_y", Role::accel_y},
                                               {"accel_z", Role::accel_z},
                                               {"status", Role::status},
                                               {"sequence", Role::sequence},
                                               {"time", Role::time},
                                               {"latency", Role::latency},
                                               {"temperature", Role::temperature},
                                               {"gyro_temperature", Role::gyro_temperature},
                                               {"accel_temperature", Role::accel_temperature},
                                               {"coil_temperature", Role::coil_temperature},
                                               {"accel_sensor_temperature", Role::accel_sensor_temperature},
                                               {"serial", Role::serial}}};

// A unit: SI factor and whether the quantity is an increment or a rate.
struct Unit {
  const char* name;
  double si;
  Measures measures;
};
constexpr std::array<Unit, 6> kGyroUnits = {{{"rad", 1.0, Measures::increment},
                                             {"deg", kPi / 180.0, Measures::increment},
                                             {"arcsec", kPi / 180.0 / 3600.0, Measures::increment},
                                             {"rad/s", 1.0, Measures::rate},
                                             {"deg/s", kPi / 180.0, Measures::rate},
                                             {"deg/h", kPi / 180.0 / 3600.0, Measures::rate}}};
constexpr std::array<Unit, 5> kAccelUnits = {{{"m/s", 1.0, Measures::increment},
                                              {"ft/s", kFoot_m, Measures::increment},
                                              {"m/s^2", 1.0, Measures::rate},
                                              {"ft/s^2", kFoot_m, Measures::rate},
                                              {"g", kStandardGravity_mps2, Measures::rate}}};
constexpr std::array<Unit, 4> kTimeUnits = {{{"ns", 1.0, Measures::other},
                                             {"us", 1e3, Measures::other},
                                             {"ms", 1e6, Measures::other},
                                             {"s", 1e9, Measures::other}}};
constexpr std::array<Unit, 1> kTemperatureUnits = {{{"C", 1.0, Measures::other}}};

struct CrcPreset {
  const char* name;
  int width;
  std::uint32_t poly, init;
  bool reflect_in, reflect_out;
  std::uint32_t xor_out;
};
// From the "Catalogue of parametrised CRC algorithms" (reveng); check values in the tests.
constexpr std::array<CrcPreset, 8> kCrcPresets = {{
    {"crc-32", 32, 0x04C11DB7u, 0xFFFFFFFFu, true, true, 0xFFFFFFFFu},         // zlib, IEEE 802.3
    {"crc-32/mpeg-2", 32, 0x04C11DB7u, 0xFFFFFFFFu, false, false, 0x0u},      // KVH 1750/1775
    {"crc-32c", 32, 0x1EDC6F41u, 0xFFFFFFFFu, true, true, 0xFFFFFFFFu},       // Castagnoli
    {"crc-16/ibm-3740", 16, 0x1021u, 0xFFFFu, false, false, 0x0u},            // "CCITT-FALSE"
    {"crc-16/xmodem", 16, 0x1021u, 0x0u, false, false, 0x0u},
    {"crc-16/kermit", 16, 0x1021u, 0x0u, true, true, 0x0u},
    {"crc-16/modbus", 16, 0x8005u, 0xFFFFu, true, true, 0x0u},
    {"crc-8/smbus", 8, 0x07u, 0x0u, false, false, 0x0u},
}};

template <class Table>
std::string names_of(const Table& table) {
  std::string s;
  for (const auto& e : table) s += (s.empty() ? "" : ", ") + std::string(e.name);
  return s;
}

// The descriptions are read with the one strict reader (core/json_reader.hpp), throwing at the
// first problem: later checks need the values read before (field offsets against the length).
ObjectReader reader(const json& j, const std::string& where, const std::string& who) {
  return ObjectReader(j, where, ObjectReader::ThrowAtFirst{who});
}

// An unsigned integer, written as a JSON number or a "0x..." string (masks, polynomials).
std::optional<std::uint64_t> unsigned_int(ObjectReader& r, const char* key, std::uint64_t max, bool required = false) {
  const json* v = r.get(key, required);
  if (!v) return std::nullopt;
  std::uint64_t value = 0;
  if (v->is_number_unsigned()) {
    value = v->get<std::uint64_t>();
  } else if (v->is_string()) {
    const std::string s = v->get<std::string>();
    std::size_t used = 0;
    try {
      value = std::stoull(s, &used, 0);
    } catch (const std::exception&) {
      used = 0;
    }
    if (used == 0 || used != s.size()) r.fail(r.at(key), "\"" + s + "\" is not an integer (decimal or 0x hex)");
  } else {
    r.fail(r.at(key), "must be a non-negative integer (or a \"0x...\" string)");
  }
  if (value > max) r.fail(r.at(key), "must be at most " + std::to_string(max));
  return value;
}

// One of a table's named entries.
template <class Table>
auto choice(ObjectReader& r, const char* key, const Table& table, bool required = false)
    -> std::optional<typename Table::value_type> {
  const auto s = r.string(key, required);
  if (!s) return std::nullopt;
  for (const auto& e : table)
    if (*s == e.name) return e;
  r.fail(r.at(key), "\"" + *s + "\" is not one of " + names_of(table));
}

// The required forms, for the throwing reader these descriptions are read with: never nothing.
template <class Table>
auto required_choice(ObjectReader& r, const char* key, const Table& table) -> typename Table::value_type {
  if (auto e = choice(r, key, table, true)) return *e;
  r.fail(r.at(key), "is required: one of " + names_of(table));
}
std::uint64_t required_unsigned(ObjectReader& r, const char* key, std::uint64_t max) {
  if (const auto v = unsigned_int(r, key, max, true)) return *v;
  r.fail(r.at(key), "is required: a whole number up to " + std::to_string(max));
}

std::vector<std::uint8_t> parse_hex_bytes(const std::string& text, const ObjectReader& r, const std::string& path) {
  std::vector<std::uint8_t> out;
  std::string digits;
  for (const char c : text) {
    if (c == ' ' || c == ':' || c == '-') continue;
    if (!std::isxdigit(static_cast<unsigned char>(c))) r.fail(path, "\"" + text + "\" is not hex bytes (\"FE 81 FF 55\")");
    digits += c;
  }
  if (digits.empty() || digits.size() % 2 != 0) r.fail(path, "\"" + text + "\" must be whole hex bytes (\"FE 81 FF 55\")");
  for (std::size_t i = 0; i < digits.size(); i += 2)
    out.push_back(static_cast<std::uint8_t>(std::stoul(digits.substr(i, 2), nullptr, 16)));
  return out;
}

ByteOrder read_byte_order(ObjectReader& r, const char* key, std::optional<ByteOrder> fallback) {
  const auto s = r.string(key, !fallback.has_value());
  if (!s) {
    if (fallback) return *fallback;
    r.fail(r.at(key), "is required: \"big\" or \"little\"");
  }
  if (*s == "big") return ByteOrder::big;
  if (*s == "little") return ByteOrder::little;
  r.fail(r.at(key), "must be \"big\" or \"little\"");
}

bool is_gyro(Role r) { return r == Role::gyro_x || r == Role::gyro_y || r == Role::gyro_z; }
bool is_accel(Role r) { return r == Role::accel_x || r == Role::accel_y || r == Role::accel_z; }
bool is_temperature(Role r) {
  return r == Role::temperature || r == Role::gyro_temperature || r == Role::accel_temperature ||
         r == Role::coil_temperature || r == Role::accel_sensor_temperature;
}
std::uint64_t type_modulus_minus_one(FieldType t) {
  const std::size_t bits = 8 * type_size(t);
  return bits >= 64 ? std::numeric_limits<std::uint64_t>::max() : (std::uint64_t{1} << bits) - 1;
}

Field read_field(const json& j, const std::string& where, const std::string& who, MessageKind kind,
                 ByteOrder default_order) {
  ObjectReader r = reader(j, where, who);
  Field f;
  f.role = required_choice(r, "role", kRoles).role;
  if (kind == MessageKind::sample && (f.role == Role::coil_temperature || f.role == Role::accel_sensor_temperature))
    r.fail(r.at("role"), std::string(to_string(f.role)) + " belongs in a temperature message");
  if (kind == MessageKind::temperature && f.role != Role::sequence && f.role != Role::time &&
      f.role != Role::coil_temperature && f.role != Role::accel_sensor_temperature)
    r.fail(r.at("role"), "a temperature message carries sequence, time, coil_temperature and accel_sensor_temperature");
  if ((kind == MessageKind::identity) != (f.role == Role::serial))
    r.fail(r.at("role"), "an identity message carries the serial field, and only it");
  f.offset = static_cast<std::size_t>(required_unsigned(r, "offset", 1 << 16));
  f.type = required_choice(r, "type", kTypes).type;
  if ((f.type == FieldType::ascii) != (f.role == Role::serial))
    r.fail(r.at("type"), "the serial field is ascii, and only it");
  f.byte_order = read_byte_order(r, "byte_order", default_order);
  // A serial number is up to 64 characters (NUL- or space-padded to `count`).
  const std::size_t slots = f.role == Role::coil_temperature ? 24
                            : f.role == Role::accel_sensor_temperature ? 3
                            : f.role == Role::serial ? 64 : 1;
  if (const auto c = unsigned_int(r, "count", slots)) {
    if (slots == 1 && *c != 1) r.fail(r.at("count"), "only temperatures and the serial's characters repeat");
    if (*c == 0) r.fail(r.at("count"), "must be at least 1");
    f.count = static_cast<std::size_t>(*c);
  }
  if (const auto i = unsigned_int(r, "index", slots - 1)) f.index = static_cast<std::size_t>(*i);
  if (f.role == Role::serial && !r.has("count")) r.fail(where, "the serial field needs count (its characters)");
  if (f.index + f.count > slots)
    r.fail(where, "index + count must stay within the " + std::to_string(slots) + " " + to_string(f.role) + " slots");

  // The unit: SI factor, and for the inertial channels whether it is an increment or a rate.
  std::optional<Unit> unit;
  if (is_gyro(f.role)) {
    unit = required_choice(r, "unit", kGyroUnits);
  } else if (is_accel(f.role)) {
    unit = required_choice(r, "unit", kAccelUnits);
  } else if (f.role == Role::time || f.role == Role::latency) {
    unit = required_choice(r, "unit", kTimeUnits);
  } else if (is_temperature(f.role)) {
    unit = required_choice(r, "unit", kTemperatureUnits);
  }
  if (unit) f.measures = unit->measures;

  // The LSB: a number, or "per-unit" for integer increments whose LSB the device configuration
  // gives (imucal's CAN layout: the resolution depends on the unit and its rate).
  double lsb = 1.0;
  bool per_unit = false;
  if (const json* v = r.get("lsb", false)) {
    if (v->is_string() && v->get<std::string>() == "per-unit") {
      if (!(is_gyro(f.role) || is_accel(f.role)) || f.measures != Measures::increment || !is_integer(f.type))
        r.fail(r.at("lsb"), "\"per-unit\" is for integer gyro or accelerometer increments only");
      per_unit = true;
    } else if (v->is_number() && std::isfinite(v->get<double>()) && v->get<double>() > 0.0) {
      lsb = v->get<double>();
    } else {
      r.fail(r.at("lsb"), "must be a positive number (the value of one count in the field's unit) or \"per-unit\"");
    }
  }
  if (!unit && r.has("lsb")) r.fail(r.at("lsb"), std::string("a ") + to_string(f.role) + " field has no LSB");
  if (!unit && r.has("unit")) r.fail(r.at("unit"), std::string("a ") + to_string(f.role) + " field has no unit");
  if (!unit) r.get("unit", false);
  f.scale = per_unit ? std::nullopt : std::optional<double>(lsb * (unit ? unit->si : 1.0));

  if (f.role == Role::status || f.role == Role::sequence || f.role == Role::time || f.role == Role::latency) {
    if (!is_integer(f.type) || is_signed(f.type))
      r.fail(r.at("type"), std::string("a ") + to_string(f.role) + " field is an unsigned integer");
  }
  if (const auto m = unsigned_int(r, "fault_when_set", type_modulus_minus_one(f.type))) f.fault_when_set = *m;
  if (const auto m = unsigned_int(r, "fault_when_clear", type_modulus_minus_one(f.type))) f.fault_when_clear = *m;
  if ((f.fault_when_set || f.fault_when_clear) && f.role != Role::status)
    r.fail(where, "fault_when_set/fault_when_clear belong to the status field");
  if (const auto w = unsigned_int(r, "wrap", std::numeric_limits<std::uint64_t>::max())) {
    if (f.role != Role::sequence && f.role != Role::time) r.fail(r.at("wrap"), "only a sequence or time field wraps");
    if (*w < 2 || (type_size(f.type) < 8 && *w - 1 > type_modulus_minus_one(f.type)))
      r.fail(r.at("wrap"), "must be 2 .. 2^bits of the field's type");
    f.wrap = *w;
  }
  if (const json* v = r.get("invalid", false)) {
    if (!v->is_number_integer() || !is_integer(f.type) || !is_temperature(f.role))
      r.fail(r.at("invalid"), "is an integer raw value meaning \"no sensor\", for integer temperature fields");
    f.invalid_raw = v->get<std::int64_t>();
  }
  r.finish();
  return f;
}

Checksum read_checksum(const json& j, const std::string& where, const std::string& who, std::size_t length,
                       ByteOrder default_order) {
  ObjectReader r = reader(j, where, who);
  Checksum c;
  const std::string type = r.required_string("type");
  if (type == "crc") {
    c.kind = ChecksumKind::crc;
    if (const auto preset = r.string("preset")) {
      const auto it = std::find_if(kCrcPresets.begin(), kCrcPresets.end(), [&](const CrcPreset& p) { return *preset == p.name; });
      if (it == kCrcPresets.end()) r.fail(r.at("preset"), "\"" + *preset + "\" is not one of " + names_of(kCrcPresets));
      c.width_bits = it->width;
      c.poly = it->poly;
      c.init = it->init;
      c.reflect_in = it->reflect_in;
      c.reflect_out = it->reflect_out;
      c.xor_out = it->xor_out;
      for (const char* k : {"width", "poly", "init", "reflect_in", "reflect_out", "xor_out"})
        if (r.has(k)) r.fail(r.at(k), "give a preset or the parameters, not both");
    } else {
      const std::uint64_t width = required_unsigned(r, "width", 32);
      if (width != 8 && width != 16 && width != 32) r.fail(r.at("width"), "must be 8, 16 or 32");
      c.width_bits = static_cast<int>(width);
      const std::uint64_t max = (std::uint64_t{1} << width) - 1;
      c.poly = static_cast<std::uint32_t>(required_unsigned(r, "poly", max));
      c.init = static_cast<std::uint32_t>(unsigned_int(r, "init", max).value_or(0));
      c.xor_out = static_cast<std::uint32_t>(unsigned_int(r, "xor_out", max).value_or(0));
      c.reflect_in = r.boolean("reflect_in").value_or(false);
      c.reflect_out = r.boolean("reflect_out").value_or(false);
    }
  } else if (type == "sum8") {
    c.kind = ChecksumKind::sum8;
  } else if (type == "xor8") {
    c.kind = ChecksumKind::xor8;
  } else {
    r.fail(r.at("type"), "\"" + type + "\" is not one of crc, sum8, xor8");
  }
  c.offset = static_cast<std::size_t>(required_unsigned(r, "offset", length));
  c.from = static_cast<std::size_t>(unsigned_int(r, "from", length).value_or(0));
  c.to = static_cast<std::size_t>(unsigned_int(r, "to", length).value_or(c.offset));
  c.byte_order = read_byte_order(r, "byte_order", default_order);
  if (c.from >= c.to) r.fail(where, "from must be below to (the checksum covers bytes [from, to))");
  if (c.offset + c.size() > length) r.fail(r.at("offset"), "the checksum must lie within the frame's length");
  if (c.offset < c.to && c.offset + c.size() > c.from) r.fail(r.at("offset"), "the checksum cannot cover itself");
  r.finish();
  return c;
}

Command read_command(const json& j, const std::string& where, const std::string& who, Transport t) {
  ObjectReader r = reader(j, where, who);
  Command c;
  c.bytes = parse_hex_bytes(r.required_string("bytes"), r, r.at("bytes"));
  if (const auto id = unsigned_int(r, "can_id", 0x7FF)) c.can_id = static_cast<std::uint32_t>(*id);
  if (t == Transport::socketcan) {
    if (!c.can_id) r.fail(r.at("can_id"), "is required on CAN");
    if (c.bytes.size() > 8) r.fail(r.at("bytes"), "a classic CAN frame carries at most 8 bytes");
  } else if (c.can_id) {
    r.fail(r.at("can_id"), "only for a socketcan transport");
  }
  r.finish();
  return c;
}

Message read_message(const json& j, const std::string& where, const std::string& who, Transport t,
                     ByteOrder default_order) {
  ObjectReader r = reader(j, where, who);
  Message m;
  m.name = r.required_string("name");
  const auto kind = r.string("kind", true);
  if (*kind == "sample") {
    m.kind = MessageKind::sample;
  } else if (*kind == "temperature") {
    m.kind = MessageKind::temperature;
  } else if (*kind == "identity") {
    m.kind = MessageKind::identity;
  } else {
    r.fail(r.at("kind"), "must be \"sample\", \"temperature\" or \"identity\"");
  }
  if (const auto h = r.string("header")) m.header = parse_hex_bytes(*h, r, r.at("header"));
  if (t != Transport::socketcan && m.header.size() < 2)
    r.fail(r.at("header"), "a serial or UDP frame needs a sync header of at least 2 bytes");
  m.length = static_cast<std::size_t>(required_unsigned(r, "length", 4096));
  if (m.length <= m.header.size()) r.fail(r.at("length"), "must exceed the header");
  if (const json* c = r.get("checksum", t != Transport::socketcan))
    m.checksum = read_checksum(*c, r.at("checksum"), who, m.length, default_order);
  if (const auto id = unsigned_int(r, "can_id", 0x7FF)) m.can_id = static_cast<std::uint32_t>(*id);
  if (const auto id = unsigned_int(r, "classic_base_id", 0x7FF)) m.classic_base_id = static_cast<std::uint32_t>(*id);
  if (t == Transport::socketcan) {
    if (!m.can_id && !m.classic_base_id) r.fail(where, "a CAN message needs can_id (CAN FD) and/or classic_base_id");
    if (m.length > 64) r.fail(r.at("length"), "a CAN message carries at most 64 bytes");
  } else if (m.can_id || m.classic_base_id) {
    r.fail(where, "can_id and classic_base_id are for a socketcan transport");
  }
  if (const auto c = r.boolean("completes")) {
    if (m.kind != MessageKind::temperature) r.fail(r.at("completes"), "only temperature messages come in sets");
    m.completes = *c;
  }
  const json* fields = r.get("fields", true);
  if (!fields->is_array()) r.fail(r.at("fields"), "must be an array");
  std::vector<std::pair<std::size_t, std::size_t>> used;  // byte ranges
  if (!m.header.empty()) used.emplace_back(0, m.header.size());
  if (m.checksum.kind != ChecksumKind::none) used.emplace_back(m.checksum.offset, m.checksum.offset + m.checksum.size());
  for (std::size_t i = 0; i < fields->size(); ++i) {
    const std::string fw = r.at("fields") + "[" + std::to_string(i) + "]";
    Field f = read_field((*fields)[i], fw, who, m.kind, default_order);
    const std::size_t end = f.offset + f.count * type_size(f.type);
    if (end > m.length) r.fail(fw, "ends at byte " + std::to_string(end) + ", beyond the frame's length " + std::to_string(m.length));
    for (const auto& [b, e] : used)
      if (f.offset < e && end > b) r.fail(fw, "overlaps the header, the checksum or another field");
    used.emplace_back(f.offset, end);
    if (f.role != Role::coil_temperature && f.role != Role::accel_sensor_temperature && m.find(f.role))
      r.fail(fw, std::string("a second ") + to_string(f.role) + " field");
    m.fields.push_back(f);
  }
  if (m.kind == MessageKind::identity && !m.find(Role::serial))
    r.fail(r.at("fields"), "an identity message needs a serial field");
  if (m.kind == MessageKind::sample) {
    for (Role need : {Role::gyro_x, Role::gyro_y, Role::gyro_z, Role::accel_x, Role::accel_y, Role::accel_z, Role::sequence})
      if (!m.find(need)) r.fail(r.at("fields"), std::string("a sample message needs a ") + to_string(need) + " field");
  }
  r.finish();
  return m;
}

}  // namespace

std::size_t Checksum::size() const noexcept {
  switch (kind) {
    case ChecksumKind::none: return 0;
    case ChecksumKind::crc: return static_cast<std::size_t>(width_bits / 8);
    case ChecksumKind::sum8:
    case ChecksumKind::xor8: return 1;
  }
  return 0;
}

const Field* Message::find(Role role) const noexcept {
  for (const Field& f : fields)
    if (f.role == role) return &f;
  return nullptr;
}

std::size_t ImuLink::sample_message() const noexcept {
  for (std::size_t i = 0; i < messages.size(); ++i)
    if (messages[i].kind == MessageKind::sample) return i;
  return 0;  // the parser guarantees one
}

bool ImuLink::reports_serial() const noexcept {
  for (const Message& m : messages)
    if (m.kind == MessageKind::identity) return true;
  return false;
}

std::size_t ImuLink::max_length() const noexcept {
  std::size_t n = 0;
  for (const Message& m : messages) n = std::max(n, m.length);
  return n;
}

namespace {
std::optional<double> increment_lsb(const ImuLink& link, std::array<Role, 3> roles) {
  const Message& m = link.messages[link.sample_message()];
  std::optional<double> lsb;
  for (Role role : roles) {
    const Field* f = m.find(role);
    if (!f || !is_integer(f->type) || f->measures != Measures::increment || !f->scale) return std::nullopt;
    if (lsb && *lsb != *f->scale) return std::nullopt;
    lsb = f->scale;
  }
  return lsb;
}
bool per_unit(const ImuLink& link, std::array<Role, 3> roles) {
  const Message& m = link.messages[link.sample_message()];
  for (Role role : roles)
    if (const Field* f = m.find(role); f && !f->scale) return true;
  return false;
}
}  // namespace

std::optional<double> ImuLink::gyro_increment_lsb_rad() const noexcept {
  return increment_lsb(*this, {Role::gyro_x, Role::gyro_y, Role::gyro_z});
}
std::optional<double> ImuLink::accel_increment_lsb_mps() const noexcept {
  return increment_lsb(*this, {Role::accel_x, Role::accel_y, Role::accel_z});
}
bool ImuLink::gyro_lsb_per_unit() const noexcept { return per_unit(*this, {Role::gyro_x, Role::gyro_y, Role::gyro_z}); }
bool ImuLink::accel_lsb_per_unit() const noexcept {
  return per_unit(*this, {Role::accel_x, Role::accel_y, Role::accel_z});
}

const char* to_string(Transport t) noexcept {
  switch (t) {
    case Transport::socketcan: return "socketcan";
    case Transport::serial: return "serial";
    case Transport::udp: return "udp";
  }
  return "?";
}

const char* to_string(Role r) noexcept {
  for (const auto& e : kRoles)
    if (e.role == r) return e.name;
  return "?";
}

std::size_t type_size(FieldType t) noexcept {
  switch (t) {
    case FieldType::u8:
    case FieldType::i8:
    case FieldType::ascii: return 1;
    case FieldType::u16:
    case FieldType::i16: return 2;
    case FieldType::u32:
    case FieldType::i32:
    case FieldType::f32: return 4;
    case FieldType::u64:
    case FieldType::i64:
    case FieldType::f64: return 8;
  }
  return 1;
}

bool is_integer(FieldType t) noexcept { return t != FieldType::f32 && t != FieldType::f64; }
bool is_signed(FieldType t) noexcept {
  return t == FieldType::i8 || t == FieldType::i16 || t == FieldType::i32 || t == FieldType::i64 ||
         t == FieldType::f32 || t == FieldType::f64;
}

ImuLink imu_link_from_json(const std::string& json_text) {
  json j;
  try {
    j = json::parse(json_text);
  } catch (const json::exception& e) {
    throw std::invalid_argument(std::string("imu link: not valid JSON: ") + e.what());
  }
  const std::string who = "imu link '" + (j.is_object() && j.contains("name") && j["name"].is_string()
                                              ? j["name"].get<std::string>()
                                              : std::string("?")) +
                          "': ";
  ObjectReader r = reader(j, "", who);
  if (r.string("format", true) != std::string(kFormat)) r.fail("format", std::string("must be \"") + kFormat + "\"");
  ImuLink link;
  link.name = r.required_string("name");
  if (link.name.empty()) r.fail("name", "must not be empty");
  link.source = r.required_string("source");
  const ByteOrder order = read_byte_order(r, "byte_order", std::nullopt);
  {
    ObjectReader t = reader(r.required("transport"), "transport", who);
    const std::string type = t.required_string("type");
    if (type == "socketcan") {
      link.transport = Transport::socketcan;
    } else if (type == "serial") {
      link.transport = Transport::serial;
      link.serial.baud = static_cast<unsigned>(required_unsigned(t, "baud", 20'000'000));
      if (link.serial.baud < 50) t.fail(t.at("baud"), "must be at least 50");
      if (const auto p = t.string("parity")) {
        if (*p == "none") link.serial.parity = Parity::none;
        else if (*p == "odd") link.serial.parity = Parity::odd;
        else if (*p == "even") link.serial.parity = Parity::even;
        else t.fail(t.at("parity"), "must be \"none\", \"odd\" or \"even\"");
      }
      if (const auto d = unsigned_int(t, "data_bits", 8)) {
        if (*d < 5) t.fail(t.at("data_bits"), "must be 5..8");
        link.serial.data_bits = static_cast<unsigned>(*d);
      }
      if (const auto s = unsigned_int(t, "stop_bits", 2)) {
        if (*s < 1) t.fail(t.at("stop_bits"), "must be 1 or 2");
        link.serial.stop_bits = static_cast<unsigned>(*s);
      }
    } else if (type == "udp") {
      link.transport = Transport::udp;
    } else {
      t.fail(t.at("type"), "\"" + type + "\" is not one of socketcan, serial, udp");
    }
    t.finish();
  }
  const json* messages = r.get("messages", true);
  if (!messages->is_array() || messages->empty()) r.fail("messages", "must be a non-empty array");
  std::set<std::string> names;
  for (std::size_t i = 0; i < messages->size(); ++i) {
    const std::string where = "messages[" + std::to_string(i) + "]";
    link.messages.push_back(read_message((*messages)[i], where, who, link.transport, order));
    if (!names.insert(link.messages.back().name).second) r.fail(where + ".name", "a second message of that name");
  }
  const auto samples = std::count_if(link.messages.begin(), link.messages.end(),
                                     [](const Message& m) { return m.kind == MessageKind::sample; });
  if (samples != 1) r.fail("messages", "must hold exactly one sample message");
  // Frames must be told apart: by CAN identifier on CAN, else by their headers.
  for (std::size_t a = 0; a < link.messages.size(); ++a) {
    for (std::size_t b = a + 1; b < link.messages.size(); ++b) {
      const Message& ma = link.messages[a];
      const Message& mb = link.messages[b];
      const auto prefix = std::min(ma.header.size(), mb.header.size());
      const bool same_header = std::equal(ma.header.begin(), ma.header.begin() + static_cast<std::ptrdiff_t>(prefix), mb.header.begin());
      const bool same_id = ma.can_id == mb.can_id && ma.classic_base_id == mb.classic_base_id;
      if (same_header && (link.transport != Transport::socketcan || same_id))
        r.fail("messages[" + std::to_string(b) + "].header", "cannot be told apart from message '" + ma.name + "'");
    }
  }
  const auto completing = std::count_if(link.messages.begin(), link.messages.end(), [](const Message& m) {
    return m.kind == MessageKind::temperature && m.completes;
  });
  const auto temperature = std::count_if(link.messages.begin(), link.messages.end(),
                                         [](const Message& m) { return m.kind == MessageKind::temperature; });
  if (temperature > 0 && completing != 1) r.fail("messages", "exactly one temperature message completes a set (\"completes\": true)");
  if (temperature > 1) {
    for (std::size_t i = 0; i < link.messages.size(); ++i)
      if (link.messages[i].kind == MessageKind::temperature && !link.messages[i].find(Role::sequence))
        r.fail("messages[" + std::to_string(i) + "].fields", "temperature messages in a set need a sequence field to join them");
  }
  if (const json* c = r.get("start", false)) link.start = read_command(*c, "start", who, link.transport);
  if (const json* c = r.get("stop", false)) link.stop = read_command(*c, "stop", who, link.transport);
  r.finish();
  return link;
}

std::vector<std::string> builtin_imu_link_names() { return embedded_names(builtin::kImuLinks); }

std::string builtin_imu_link_json(const std::string& name) { return embedded_text(builtin::kImuLinks, name, "IMU link"); }

ImuLink load_imu_link(const std::string& name_or_path) {
  return imu_link_from_json(embedded_or_file_text(builtin::kImuLinks, name_or_path, "IMU link"));
}

void resolve_per_unit_lsb(ImuLink& link, std::optional<double> gyro_lsb_rad, std::optional<double> accel_lsb_mps) {
  const std::string who = "imu link '" + link.name + "': ";
  for (const auto& [per_unit_here, lsb, what] :
       {std::tuple{link.gyro_lsb_per_unit(), gyro_lsb_rad, "gyro_lsb_rad"},
        std::tuple{link.accel_lsb_per_unit(), accel_lsb_mps, "accel_lsb_mps"}}) {
    if (per_unit_here && !lsb)
      throw std::invalid_argument(who + "its increments have a per-unit LSB: " + what + " is required");
    if (!per_unit_here && lsb)
      throw std::invalid_argument(who + "the description fixes the LSB of its increments: " + what + " cannot be given");
    if (lsb && !(*lsb > 0.0 && std::isfinite(*lsb))) throw std::invalid_argument(who + what + " must be positive");
  }
  for (Message& m : link.messages) {
    for (Field& f : m.fields) {
      if (f.scale) continue;
      f.scale = is_gyro(f.role) ? gyro_lsb_rad : accel_lsb_mps;
    }
  }
}

}  // namespace imucal::drivers::link
