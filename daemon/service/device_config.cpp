#include "daemon/service/device_config.hpp"

#include <sys/un.h>

#include <array>
#include <cmath>
#include <cstdio>
#include <exception>
#include <optional>
#include <span>

#include <nlohmann/json.hpp>

#include "daemon/service/json_reader.hpp"

namespace imucal::daemon {

using nlohmann::json;
namespace dr = imucal::drivers;

namespace {

// The keys of imucal-table/1 and imucal-chamber/1 (drivers/acl_table.hpp, modbus_chamber.hpp).
// The drivers' parsers ignore keys they do not know; the daemon's configuration refuses them, so
// that a typo (`"watchdog"`) never becomes a silent default.
constexpr std::array<const char*, 11> kTableKeys = {
    "format",         "host",           "port",       "response_timeout_ms",  "connect_timeout_ms", "backoff_initial_ms",
    "backoff_max_ms", "reply_checksum", "watchdog_s", "safe_stop_timeout_ms", "limits"};
constexpr std::array<const char*, 15> kChamberKeys = {
    "format",    "transport", "host", "port", "serial_device",       "baud",           "parity",          "data_bits",
    "stop_bits", "map",       "response_timeout_ms", "backoff_initial_ms", "backoff_max_ms", "safe_setpoint_C",
    "setpoint_range_C"};

// A driver's message starts with its own context ("table config: "); the key path replaces it.
// nlohmann's "[json.exception.type_error.302] " tag says nothing to an operator either.
std::string without_prefix(const std::string& message, const std::string& prefix) {
  std::string m = message.rfind(prefix, 0) == 0 ? message.substr(prefix.size()) : message;
  if (m.rfind("[json.exception.", 0) == 0) {
    if (const auto end = m.find("] "); end != std::string::npos) m.erase(0, end + 2);
  }
  return m;
}

// One device object in a driver's own configuration form. Each key is first given to the
// driver's parser alone (on `base`, which holds whatever the parser requires besides it), so that
// every bad value is reported with its own key path rather than only the first; then the whole
// object, for the rules that tie keys together.
template <class Config, class Parse>
std::optional<Config> read_driver_object(const json& j, const std::string& where, std::span<const char* const> keys,
                                         const std::string& format, const std::string& driver_prefix,
                                         const std::vector<std::string>& required, const json& base, Parse parse,
                                         std::vector<std::string>& problems) {
  ObjectReader r(j, where, problems);
  if (!r.is_object()) return std::nullopt;
  const std::size_t before = problems.size();
  json clean = json::object();  // without the '_' comments
  for (const char* key : keys)
    if (const json* v = r.get(key)) clean[key] = *v;
  r.finish();
  for (const std::string& key : required)
    if (!clean.contains(key)) problems.push_back(where + "." + key + " is required");
  if (const auto it = clean.find("format"); it != clean.end()) {
    if (!it->is_string() || it->get<std::string>() != format)
      problems.push_back(where + ".format must be \"" + format + "\" when given");
    clean.erase("format");
  }
  for (const auto& [key, value] : clean.items()) {
    json alone = base;
    alone[key] = value;
    try {
      (void)parse(alone.dump());
    } catch (const std::exception& e) {
      problems.push_back(where + "." + key + ": " + without_prefix(e.what(), driver_prefix));
    }
  }
  if (problems.size() != before) return std::nullopt;
  try {
    return parse(clean.dump());
  } catch (const std::exception& e) {
    problems.push_back(where + ": " + without_prefix(e.what(), driver_prefix));
    return std::nullopt;
  }
}

std::optional<dr::AclTableConfig> read_table(const json& j, const std::string& where, std::vector<std::string>& problems) {
  // A real controller has no default address worth guessing.
  return read_driver_object<dr::AclTableConfig>(j, where, kTableKeys, "imucal-table/1", "table config: ",
                                                {"host", "port"}, json::object(), dr::acl_table_config_from_json,
                                                problems);
}

std::optional<dr::ModbusChamberConfig> read_chamber(const json& j, const std::string& where,
                                                    std::vector<std::string>& problems) {
  std::vector<std::string> required = {"map"};
  const bool rtu = j.is_object() && j.contains("transport") && j["transport"] == "rtu";
  if (rtu) {
    required.push_back("serial_device");
  } else {
    required.push_back("host");
    required.push_back("port");
  }
  // The parser requires a map: a key other than "map" is checked on a built-in one.
  return read_driver_object<dr::ModbusChamberConfig>(j, where, kChamberKeys, "imucal-chamber/1", "chamber config: ",
                                                     required, json{{"map", "watlow-f4t"}},
                                                     dr::modbus_chamber_config_from_json, problems);
}

ImuDeviceConfig read_imu(const json& j, const std::string& where, std::vector<std::string>& problems) {
  ImuDeviceConfig c;
  ObjectReader r(j, where, problems);
  if (!r.is_object()) return c;
  const auto interface = r.string("interface");
  const auto socket = r.string("socket");
  if (interface && socket) {
    problems.push_back(where + ": give \"interface\" (a CAN interface) or \"socket\" (a Unix socket path), not both");
  } else if (!interface && !socket && !r.has("interface") && !r.has("socket")) {
    problems.push_back(where + ".interface (a CAN interface such as \"can0\") or " + where +
                       ".socket (a Unix SOCK_SEQPACKET socket path) is required");
  }
  if (interface) {
    // IFNAMSIZ is 16 with the terminating zero.
    if (interface->empty() || interface->size() > 15)
      problems.push_back(r.at("interface") + " must have 1 to 15 characters, not " + std::to_string(interface->size()));
    c.interface = *interface;
  }
  if (socket) {
    if (socket->empty() || socket->size() >= sizeof(sockaddr_un{}.sun_path))
      problems.push_back(r.at("socket") + " must be a path of 1 to " + std::to_string(sizeof(sockaddr_un{}.sun_path) - 1) +
                         " characters");
    c.socket_path = *socket;
  }
  if (auto v = r.string("framing")) {
    if (*v == "fd") {
      c.framing = dr::can::Framing::fd;
    } else if (*v == "classic") {
      c.framing = dr::can::Framing::classic;
    } else {
      problems.push_back(r.at("framing") + " must be \"fd\" or \"classic\"");
    }
  }
  if (auto v = r.number_in("rate_hz", 1, 100000, true)) c.rate_hz = *v;
  for (const auto& [key, target] : {std::pair<const char*, double*>{"gyro_lsb_rad", &c.gyro_lsb_rad},
                                    {"accel_lsb_mps", &c.accel_lsb_mps}}) {
    if (auto v = r.number(key, true)) {
      if (*v <= 0.0)
        problems.push_back(r.at(key) + " must be positive (one count of the increments)");
      else
        *target = *v;
    }
  }
  if (auto v = r.string("serial", true)) {
    if (v->empty()) problems.push_back(r.at("serial") + " must not be empty (it names the IMU in every run)");
    c.serial = *v;
  }
  if (auto v = r.integer("transport_delay_ns", 0, 1'000'000'000)) c.transport_delay_ns = *v;
  if (auto v = r.integer("stall_timeout_ms", 1, 60'000)) c.stall_timeout_ms = *v;
  if (c.framing == dr::can::Framing::classic && c.rate_hz > dr::can::kClassicMaxRate_hz)
    problems.push_back(where + ": classic CAN framing carries at most " + json(dr::can::kClassicMaxRate_hz).dump() +
                       " samples/s; rate_hz is " + json(c.rate_hz).dump() + " (use \"framing\": \"fd\")");
  return c;
}

}  // namespace

dr::AxisLimitSetting table_limit_setting(const motion::AxisLimits& l) {
  // The wire protocol carries finite numbers: slip rings become a range no program reaches.
  dr::AxisLimitSetting s;
  s.min_deg = std::isfinite(l.min_deg) ? l.min_deg : -1e9;
  s.max_deg = std::isfinite(l.max_deg) ? l.max_deg : 1e9;
  s.rate_dps = l.rate_dps;
  s.accel_dps2 = l.accel_dps2;
  return s;
}

std::string ImuDeviceConfig::describe() const {
  const char* framing_name = framing == dr::can::Framing::fd ? "CAN FD" : "classic CAN";
  if (!interface.empty()) return "CAN interface '" + interface + "' (" + framing_name + ")";
  return "socket " + socket_path + " (" + framing_name + " frames)";
}

DeviceAddresses read_device_addresses(const json& devices, const std::string& where,
                                      std::vector<std::string>& problems) {
  DeviceAddresses d;
  ObjectReader r(devices, where, problems);
  if (!r.is_object()) return d;
  if (const json* v = r.get("table", true)) {
    if (auto t = read_table(*v, r.at("table"), problems)) d.table = std::move(*t);
  }
  if (const json* v = r.get("chamber", true)) {
    if (auto c = read_chamber(*v, r.at("chamber"), problems)) d.chamber = std::move(*c);
  }
  if (const json* v = r.get("imu", true)) d.imu = read_imu(*v, r.at("imu"), problems);
  return d;
}

}  // namespace imucal::daemon
