#include "daemon/config/device_config.hpp"

#include <sys/un.h>

#include <cmath>
#include <cstdio>
#include <exception>
#include <optional>

#include <nlohmann/json.hpp>

#include "core/json_reader.hpp"

namespace imucal::daemon {

using nlohmann::json;
namespace dr = imucal::drivers;

namespace {

// What a Modbus device object must give besides `own`: where its link is (the serial device over
// RTU, host and port over TCP); no address is worth guessing.
std::vector<std::string> modbus_required(const json& j, std::vector<std::string> own) {
  const bool rtu = j.is_object() && j.contains("transport") && j["transport"] == "rtu";
  if (rtu) {
    own.push_back("serial_device");
  } else {
    own.push_back("host");
    own.push_back("port");
  }
  return own;
}

// A driver's message starts with its own context ("table config: "); `where` replaces it. The
// drivers read with the strict reader (core/json_reader.hpp), whose messages start with the key's
// path ("port is 70000, ...") or say "unknown key"; others (a dialect that cannot be loaded) are
// put under the key they came from.
std::string driver_problem(const std::string& message, const std::string& prefix, const std::string& where,
                           const std::string& key) {
  const std::string m = message.rfind(prefix, 0) == 0 ? message.substr(prefix.size()) : message;
  if (m.rfind("unknown key", 0) == 0) return where + ": " + m;
  if (!key.empty() && m.rfind(key, 0) == 0 && m.size() > key.size() && (m[key.size()] == ' ' || m[key.size()] == '['))
    return where + "." + m;
  return where + (key.empty() ? "" : "." + key) + ": " + m;
}

// One device object in a driver's own configuration form, read by the driver's strict parser.
// Each key is first given to the parser alone (on `base`, which holds whatever the parser
// requires besides it), so that every bad value and unknown key is reported rather than only the
// first; then the whole object, for the rules that tie keys together.
template <class Config, class Parse>
std::optional<Config> read_driver_object(const json& j, const std::string& where, const std::string& driver_prefix,
                                         const std::vector<std::string>& required, const json& base, Parse parse,
                                         std::vector<std::string>& problems) {
  if (!j.is_object()) {
    problems.push_back(where + " must be an object, not " + json_type_name(j));
    return std::nullopt;
  }
  const std::size_t before = problems.size();
  for (const std::string& key : required)
    if (!j.contains(key)) problems.push_back(where + "." + key + " is required");
  for (const auto& [key, value] : j.items()) {
    if (key.rfind('_', 0) == 0) continue;  // a comment
    json alone = base;
    alone[key] = value;
    try {
      (void)parse(alone.dump());
    } catch (const std::exception& e) {
      problems.push_back(driver_problem(e.what(), driver_prefix, where, key));
    }
  }
  if (problems.size() != before) return std::nullopt;
  try {
    return parse(j.dump());
  } catch (const std::exception& e) {
    problems.push_back(driver_problem(e.what(), driver_prefix, where, ""));
    return std::nullopt;
  }
}

std::optional<dr::TcpTableConfig> read_table(const json& j, const std::string& where, std::vector<std::string>& problems) {
  // A real controller has no default address worth guessing.
  return read_driver_object<dr::TcpTableConfig>(j, where, "table config: ",
                                                {"host", "port"}, json::object(), dr::tcp_table_config_from_json,
                                                problems);
}

std::optional<dr::ModbusChamberConfig> read_chamber(const json& j, const std::string& where,
                                                    std::vector<std::string>& problems) {
  // The parser requires a map: a key other than "map" is checked on a built-in one.
  return read_driver_object<dr::ModbusChamberConfig>(j, where, "chamber config: ",
                                                     modbus_required(j, {"map"}), json{{"map", "watlow-f4t"}},
                                                     dr::modbus_chamber_config_from_json, problems);
}

std::optional<dr::PowerRelayConfig> read_power_relay(const json& j, const std::string& where,
                                                     std::vector<std::string>& problems) {
  // No default coil: a relay switched by guess could cut the wrong supply.
  return read_driver_object<dr::PowerRelayConfig>(j, where, "power relay config: ",
                                                  modbus_required(j, {"coil"}), json::object(),
                                                  dr::power_relay_config_from_json, problems);
}

// The keys of `devices.imu` that say where the link is, by transport.
bool key_belongs_to(const std::string& key, dr::link::Transport t) {
  if (key == "interface" || key == "socket" || key == "framing") return t == dr::link::Transport::socketcan;
  if (key == "serial_device") return t == dr::link::Transport::serial;
  if (key == "udp_port" || key == "udp_bind" || key == "udp_peer") return t == dr::link::Transport::udp;
  return true;
}

// "host:port" with a port 1..65535.
bool split_host_port(const std::string& text, std::string& host, int& port) {
  const auto colon = text.rfind(':');
  if (colon == std::string::npos || colon == 0) return false;
  host = text.substr(0, colon);
  try {
    std::size_t used = 0;
    port = std::stoi(text.substr(colon + 1), &used);
    return used == text.size() - colon - 1 && port >= 1 && port <= 65535;
  } catch (const std::exception&) {
    return false;
  }
}

// The pieces of read_imu, each a few keys (small functions also keep clang-tidy's optional-access
// analysis fast: it is run per function, and its cost grows steeply with a function's branches).

// The link description (`link`): a built-in name, a file path or an inline object; absent: the
// default. False when it cannot be loaded (a problem then says why).
bool read_imu_link(ObjectReader& r, ImuDeviceConfig& c, std::vector<std::string>& problems) {
  try {
    if (const json* v = r.get("link")) {
      if (v->is_string()) {
        c.link_name = v->get<std::string>();
        c.link = dr::link::load_imu_link(c.link_name);
      } else if (v->is_object()) {
        c.link = dr::link::imu_link_from_json(v->dump());
        c.link_name = c.link.name + " (inline)";
      } else {
        throw std::invalid_argument("must be a built-in description's name, a file path or an imucal-imu-link/1 object");
      }
    } else {
      c.link = dr::link::load_imu_link(c.link_name);
    }
    return true;
  } catch (const std::exception& e) {
    problems.push_back(r.at("link") + ": " + e.what());
    return false;
  }
}

// A SocketCAN link's address: `interface` or `socket` (one of them when the link is SocketCAN),
// and `framing`.
void read_can_address(ObjectReader& r, ImuDeviceConfig& c, bool socketcan, std::vector<std::string>& problems) {
  const auto interface = r.string("interface");
  const auto socket = r.string("socket");
  if (socketcan) {
    if (interface && socket) {
      problems.push_back(r.where() + ": give \"interface\" (a CAN interface) or \"socket\" (a Unix socket path), not both");
    } else if (!interface && !socket && !r.has("interface") && !r.has("socket")) {
      problems.push_back(r.where() + ".interface (a CAN interface such as \"can0\") or " + r.where() +
                         ".socket (a Unix SOCK_SEQPACKET socket path) is required");
    }
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
}

// A serial link's `serial_device` (required on one), a UDP link's `udp_port` (required on one),
// `udp_bind` and `udp_peer` (required when the link sends the IMU a start command).
void read_serial_udp_address(ObjectReader& r, ImuDeviceConfig& c, bool serial, bool udp,
                             std::vector<std::string>& problems) {
  if (auto v = r.string("serial_device", serial)) {
    if (v->empty()) problems.push_back(r.at("serial_device") + " must name a device such as /dev/ttyUSB0");
    c.serial_device = *v;
  }
  if (auto v = r.integer("udp_port", 1, 65535, udp)) c.udp_port = static_cast<int>(*v);
  if (auto v = r.string("udp_bind")) c.udp_bind = *v;
  if (auto v = r.string("udp_peer")) {
    if (!split_host_port(*v, c.udp_peer_host, c.udp_peer_port))
      problems.push_back(r.at("udp_peer") + " must be \"host:port\" (the IMU's address), not \"" + *v + "\"");
  }
  if (udp && c.link.start && c.udp_peer_host.empty())
    problems.push_back(r.at("udp_peer") + " is required: the link '" + c.link.name + "' sends the IMU a start command");
}

// The LSBs of a description that leaves them to the unit (imucal-can): one place decides.
void read_per_unit_lsb(ObjectReader& r, ImuDeviceConfig& c, bool have_link, std::vector<std::string>& problems) {
  std::optional<double> gyro_lsb, accel_lsb;
  bool lsb_ok = true;
  for (const auto& [key, target] : {std::pair<const char*, std::optional<double>*>{"gyro_lsb_rad", &gyro_lsb},
                                    {"accel_lsb_mps", &accel_lsb}}) {
    if (auto v = r.number(key)) {
      *target = *v;
      if (*v <= 0.0) {
        problems.push_back(r.at(key) + " must be positive (one count of the increments)");
        lsb_ok = false;
      }
    }
  }
  if (have_link && lsb_ok) {
    try {
      dr::link::resolve_per_unit_lsb(c.link, gyro_lsb, accel_lsb);
    } catch (const std::exception& e) {
      problems.push_back(r.where() + ": " + e.what());
    }
  }
}

// The unit's own settings besides its rate: `serial` (required), `transport_delay_ns`,
// `stall_timeout_ms`.
void read_imu_unit(ObjectReader& r, ImuDeviceConfig& c, std::vector<std::string>& problems) {
  if (auto v = r.string("serial", true)) {
    if (v->empty()) problems.push_back(r.at("serial") + " must not be empty (it names the IMU in every run)");
    c.serial = *v;
  }
  if (auto v = r.integer("transport_delay_ns", 0, 1'000'000'000)) c.transport_delay_ns = *v;
  if (auto v = r.integer("stall_timeout_ms", 1, 60'000)) c.stall_timeout_ms = *v;
}

ImuDeviceConfig read_imu(const json& j, const std::string& where, std::vector<std::string>& problems) {
  ImuDeviceConfig c;
  ObjectReader r(j, where, problems);
  if (!r.is_object()) return c;
  // The link description first: it decides which address keys apply.
  const bool have_link = read_imu_link(r, c, problems);
  const dr::link::Transport transport = c.link.transport;
  if (have_link) {
    for (const char* key : {"interface", "socket", "framing", "serial_device", "udp_port", "udp_bind", "udp_peer"})
      if (r.has(key) && !key_belongs_to(key, transport))
        problems.push_back(r.at(key) + " does not apply: the link '" + c.link.name + "' is " + dr::link::to_string(transport));
  }
  read_can_address(r, c, have_link && transport == dr::link::Transport::socketcan, problems);
  read_serial_udp_address(r, c, have_link && transport == dr::link::Transport::serial,
                          have_link && transport == dr::link::Transport::udp, problems);
  if (auto v = r.number_in("rate_hz", 1, 100000, true)) c.rate_hz = *v;
  read_per_unit_lsb(r, c, have_link, problems);
  read_imu_unit(r, c, problems);
  if (have_link && transport == dr::link::Transport::socketcan && c.framing == dr::can::Framing::classic &&
      c.rate_hz > dr::can::kClassicMaxRate_hz)
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
  switch (link.transport) {
    case dr::link::Transport::socketcan: {
      const std::string what = std::string(framing == dr::can::Framing::fd ? "CAN FD" : "classic CAN") + ", " + link.name;
      if (!interface.empty()) return "CAN interface '" + interface + "' (" + what + ")";
      return "socket " + socket_path + " (" + what + " frames)";
    }
    case dr::link::Transport::serial: return "serial device " + serial_device + " (" + link.name + ")";
    case dr::link::Transport::udp: return "UDP port " + std::to_string(udp_port) + " (" + link.name + ")";
  }
  return link.name;
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
  if (const json* v = r.get("power_relay")) d.power_relay = read_power_relay(*v, r.at("power_relay"), problems);
  return d;
}

}  // namespace imucal::daemon
