#include "daemon/config/config.hpp"

#include <unistd.h>

#include <algorithm>
#include <cctype>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <limits>
#include <sstream>
#include <tuple>

#include <boost/asio/ip/address.hpp>
#include <nlohmann/json.hpp>

#include "daemon/config/password_hash.hpp"

#include "core/earth.hpp"
#include "core/json_reader.hpp"
#include "core/table_json.hpp"

namespace imucal::daemon {

using nlohmann::json;

const char* to_string(Role role) { return role == Role::Operator ? "operator" : "viewer"; }

namespace {

constexpr double kInf = std::numeric_limits<double>::infinity();

void read_site(const json& j, DaemonConfig& c, std::vector<std::string>& problems) {
  ObjectReader r(j, "config.site", problems);
  if (auto v = r.string("name")) c.site_name = *v;
  if (auto v = r.number_in("latitude_deg", -90, 90)) c.site.latitude_deg = *v;
  if (auto v = r.number_in("longitude_deg", -180, 360)) c.site.longitude_deg = *v;
  if (auto v = r.number_in("height_m", -500, 10000)) c.site.height_m = *v;
  if (auto v = r.number_in("gravity_mps2", 9.7, 9.9)) c.site.gravity_mps2 = *v;
  if (auto v = r.number_in("middle_axis_azimuth_deg", -360, 360)) c.site.middle_axis_azimuth_deg = *v;
}

void read_axis(const json& j, const std::string& where, motion::AxisLimits& a, std::vector<std::string>& problems) {
  ObjectReader r(j, where, problems);
  // null: unlimited (slip rings)
  for (const auto& [key, target, fallback] :
       {std::tuple<const char*, double*, double>{"min_deg", &a.min_deg, -kInf}, {"max_deg", &a.max_deg, kInf}}) {
    const json* v = r.get(key);
    if (v == nullptr) continue;
    if (v->is_null()) {
      *target = fallback;
    } else if (v->is_number()) {
      *target = v->get<double>();
    } else {
      problems.push_back(r.at(key) + " must be a number or null (unlimited)");
    }
  }
  if (auto v = r.number_in("rate_dps", 1e-3, 10000)) a.rate_dps = *v;
  if (auto v = r.number_in("accel_dps2", 1e-3, 100000)) a.accel_dps2 = *v;
  if (a.min_deg >= a.max_deg) problems.push_back(where + ": min_deg must be below max_deg");
}

void read_table(const json& j, DaemonConfig& c, std::vector<std::string>& problems) {
  ObjectReader r(j, "config.table", problems);
  if (const json* lim = r.get("limits")) {
    ObjectReader l(*lim, "config.table.limits", problems);
    for (std::size_t a = 0; a < 3; ++a) {
      if (const json* ax = l.get(motion::kAxisNames[a]))
        read_axis(*ax, l.at(motion::kAxisNames[a]), c.table_limits.axis[a], problems);
    }
  }
  // The table's own errors beside its limits, in the form meta.json has them (core reads both).
  try {
    c.table_certificate = table::read_table_certificate(r);
  } catch (const std::invalid_argument& e) {
    problems.push_back(e.what());
  }
}

void read_chamber(const json& j, DaemonConfig& c, std::vector<std::string>& problems) {
  ObjectReader r(j, "config.chamber", problems);
  if (auto v = r.number_in("min_C", -100, 300)) c.chamber.limits.min_C = *v;
  if (auto v = r.number_in("max_C", -100, 300)) c.chamber.limits.max_C = *v;
  if (auto v = r.number_in("max_ramp_C_per_min", 0, 100)) c.chamber.limits.max_ramp_C_per_min = *v;
  if (auto v = r.number_in("safe_setpoint_C", -100, 300)) c.chamber.safe_setpoint_C = *v;
  if (auto v = r.number_in("tolerance_C", 0.01, 50)) c.chamber.tolerance_C = *v;
  if (auto v = r.number_in("wait_timeout_s", 1, 7 * 86400.0)) c.chamber.wait_timeout_s = *v;
  if (c.chamber.limits.min_C >= c.chamber.limits.max_C) problems.push_back("config.chamber: min_C must be below max_C");
  if (c.chamber.safe_setpoint_C < c.chamber.limits.min_C || c.chamber.safe_setpoint_C > c.chamber.limits.max_C)
    problems.push_back("config.chamber.safe_setpoint_C must lie between min_C and max_C");
}

void read_sim(const json& j, DaemonConfig& c, std::vector<std::string>& problems) {
  ObjectReader r(j, "config.sim", problems);
  if (auto v = r.number_in("rate_hz", 1, 100000)) c.sim.rate_hz = *v;
  if (auto v = r.number_in("time_scale", 0, 1e6)) c.sim.time_scale = *v;
  if (auto v = r.number_in("wire_time_scale", 1, 1000)) c.sim.wire_time_scale = *v;
  if (auto v = r.integer("seed", 0, std::numeric_limits<std::int64_t>::max())) c.sim.seed = static_cast<std::uint64_t>(*v);
  if (auto v = r.string("truth")) c.sim.truth = *v;
  if (auto v = r.string("truths_dir")) c.sim.truths_dir = *v;
  if (auto v = r.number_in("chamber_tau_s", 0.1, 1e5)) c.sim.chamber_tau_s = *v;
  if (auto v = r.number_in("home_time_s", 0, 3600)) c.sim.home_time_s = *v;
}

void read_suspenders(const json& j, DaemonConfig& c, std::vector<std::string>& problems) {
  ObjectReader r(j, "config.suspenders", problems);
  if (auto v = r.number_in("settle_s", 0, 86400)) c.suspenders.settle_s = *v;
  if (auto v = r.number_in("frame_timeout_s", 0.01, 3600)) c.suspenders.frame_timeout_s = *v;
  if (auto v = r.number_in("chamber_persist_s", 0, 3600)) c.suspenders.chamber_persist_s = *v;
}

void read_recorder(const json& j, DaemonConfig& c, std::vector<std::string>& problems) {
  ObjectReader r(j, "config.recorder", problems);
  if (auto v = r.number_in("commit_interval_s", 0.01, 60)) c.recorder.commit_interval_s = *v;
  if (auto v = r.integer("queue_frames", 4096, std::int64_t{1} << 30)) c.recorder.queue_frames = *v;
}

void read_http(const json& j, DaemonConfig& c, std::vector<std::string>& problems) {
  ObjectReader r(j, "config.http", problems);
  if (auto v = r.integer("body_limit_bytes", 1024, std::int64_t{1} << 30)) c.http.body_limit_bytes = *v;
  if (auto v = r.number_in("request_timeout_s", 0.1, 3600)) c.http.request_timeout_s = *v;
  if (auto v = r.number_in("session_idle_s", 10, 30 * 86400.0)) c.http.session_idle_s = *v;
  if (auto v = r.number_in("live_rate_hz", 0.1, 100)) c.http.live_rate_hz = *v;
  if (auto v = r.integer("live_queue", 1, 100000)) c.http.live_queue = *v;
  if (auto v = r.integer("max_connections_per_client", 1, 100000)) c.http.max_connections_per_client = *v;
  if (auto v = r.integer("max_analysis_jobs", 1, 10000)) c.http.max_analysis_jobs = *v;
  if (auto v = r.integer("exports_max_bytes", 0, std::int64_t{1} << 50)) c.http.exports_max_bytes = *v;
  if (auto v = r.integer("threads", 1, 64)) c.http.threads = static_cast<int>(*v);
  if (auto v = r.string("web_dir")) c.http.web_dir = *v;
  if (const json* v = r.get("trusted_proxies")) {
    const std::string where = r.at("trusted_proxies");
    if (!v->is_array()) {
      problems.push_back(where + " must be an array of IP addresses (the reverse proxies in front of imucald)");
    } else {
      c.http.trusted_proxies.clear();
      for (std::size_t i = 0; i < v->size(); ++i) {
        const json& a = (*v)[i];
        boost::system::error_code ec;
        if (a.is_string()) (void)boost::asio::ip::make_address(a.get<std::string>(), ec);
        if (!a.is_string() || ec)
          problems.push_back(where + "[" + std::to_string(i) + "] must be an IP address such as \"127.0.0.1\", not " +
                             json_text(a).substr(0, 80));
        else
          c.http.trusted_proxies.push_back(a.get<std::string>());
      }
    }
  }
}

void read_log(const json& j, DaemonConfig& c, std::vector<std::string>& problems) {
  ObjectReader r(j, "config.log", problems);
  if (auto v = r.string("level")) {
    static const std::vector<std::string> levels = {"trace", "debug", "info", "warn", "error", "critical", "off"};
    if (std::find(levels.begin(), levels.end(), *v) == levels.end())
      problems.push_back("config.log.level must be one of trace, debug, info, warn, error, critical, off");
    else
      c.log.level = *v;
  }
  if (auto v = r.string("file")) c.log.file = *v;
  if (auto v = r.number_in("max_size_mb", 0.01, 100000)) c.log.max_size_mb = *v;
  if (auto v = r.integer("max_files", 1, 1000)) c.log.max_files = static_cast<int>(*v);
}

// A required text that says something (a certificate must identify what it names), into `target`.
void read_required_text(ObjectReader& r, const char* key, std::string& target, std::vector<std::string>& problems) {
  if (auto v = r.string(key, true)) {
    if (v->find_first_not_of(" \t") == std::string::npos) problems.push_back(r.at(key) + " must not be empty");
    else target = *v;
  }
}

// calibration_due: required, a date of the calendar (the start check and the certificate compare it).
void read_due_date(ObjectReader& r, std::string& target, std::vector<std::string>& problems) {
  read_required_text(r, "calibration_due", target, problems);
  if (!target.empty() && !date_day_number(target)) {
    problems.push_back(r.at("calibration_due") + " must be a date YYYY-MM-DD, not \"" + target + "\"");
    target.clear();
  }
}

ReferenceInstrument read_instrument(const json& j, const std::string& where, std::vector<std::string>& problems) {
  ObjectReader r(j, where, problems);
  ReferenceInstrument out;
  // A certificate must identify the instrument completely: each of these is required.
  read_required_text(r, "make", out.make, problems);
  read_required_text(r, "model", out.model, problems);
  read_required_text(r, "serial", out.serial, problems);
  read_due_date(r, out.calibration_due, problems);
  if (auto v = r.string("calibration_certificate")) out.calibration_certificate = *v;
  if (auto v = r.string("uncertainty")) {
    if (v->find_first_not_of(" \t") == std::string::npos)
      problems.push_back(r.at("uncertainty") + " must say the uncertainty as the instrument's certificate states it "
                                              "(e.g. \"1 arcsec (k=2)\"), or be left out");
    else
      out.uncertainty = *v;
  }
  return out;
}

GravitySurvey read_gravity_survey(const json& j, const std::string& where, std::vector<std::string>& problems) {
  ObjectReader r(j, where, problems);
  GravitySurvey out;
  read_required_text(r, "surveyed_by", out.surveyed_by, problems);
  read_required_text(r, "calibration_certificate", out.calibration_certificate, problems);
  read_due_date(r, out.calibration_due, problems);
  // One number for the site's g's uncertainty: the one the calibration uses.
  if (r.has("uncertainty")) {
    (void)r.get("uncertainty");
    char sigma[32];
    std::snprintf(sigma, sizeof sigma, "%g", earth::kMeasuredGravitySigma_mps2);
    problems.push_back(r.at("uncertainty") + " is not configured: the uncertainty of a measured g is the 1-sigma the "
                                             "calibration uses for it (" + sigma + " m/s^2, core/earth.hpp), stated on "
                                             "every certificate");
  }
  return out;
}

void read_reference_equipment(const json& j, DaemonConfig& c, std::vector<std::string>& problems) {
  ObjectReader r(j, "config.reference_equipment", problems);
  if (const json* v = r.get("table")) c.reference_equipment.table = read_instrument(*v, r.at("table"), problems);
  if (const json* v = r.get("chamber")) c.reference_equipment.chamber = read_instrument(*v, r.at("chamber"), problems);
  if (const json* v = r.get("gravity")) c.reference_equipment.gravity = read_gravity_survey(*v, r.at("gravity"), problems);
}

// Letters, digits and '-', starting with a letter or digit: it goes into file names and
// certificate numbers as it is.
bool is_prefix(const std::string& text) {
  if (text.empty() || text.size() > 20 || !std::isalnum(static_cast<unsigned char>(text.front()))) return false;
  return std::all_of(text.begin(), text.end(),
                     [](char ch) { return std::isalnum(static_cast<unsigned char>(ch)) || ch == '-'; });
}

void read_certificates(const json& j, DaemonConfig& c, std::vector<std::string>& problems) {
  ObjectReader r(j, "config.certificates", problems);
  if (auto v = r.string("prefix")) {
    if (!is_prefix(*v))
      problems.push_back(r.at("prefix") + " must be 1 to 20 letters, digits or '-', starting with a letter or digit, not \"" +
                         *v + "\"");
    else
      c.certificates.prefix = *v;
  }
  if (auto v = r.string("sequence_file")) {
    if (v->empty()) problems.push_back(r.at("sequence_file") + " must name a file (relative to the configuration file or absolute)");
    else c.certificates.sequence_file = *v;
  }
  if (auto v = r.string("signing_key_file")) {
    if (v->empty()) problems.push_back(r.at("signing_key_file") + " must name the lab's key file (imucal keygen), or be left out");
    else c.certificates.signing_key_file = *v;
  }
}

void read_registry(const json& j, DaemonConfig& c, std::vector<std::string>& problems) {
  ObjectReader r(j, "config.registry", problems);
  if (auto v = r.string("postgresql")) {
    if (v->empty()) problems.push_back(r.at("postgresql") + " must be a PostgreSQL connection string (libpq's), or be left out");
    else c.registry.postgresql = *v;
  }
  if (auto v = r.string("stand")) {
    if (v->empty()) problems.push_back(r.at("stand") + " must name this stand, or be left out (the host's name)");
    else c.registry.stand = *v;
  }
  if (auto v = r.string("url")) {
    if (!v->starts_with("http://") && !v->starts_with("https://"))
      problems.push_back(r.at("url") + " must be this stand's address as a browser reaches it (http://... or https://...)");
    else c.registry.url = *v;
  }
  if (auto v = r.number_in("heartbeat_s", 0.05, 600)) c.registry.heartbeat_s = *v;
  if (auto v = r.string("archive_dir")) {
    if (v->empty()) problems.push_back(r.at("archive_dir") + " must name the lab's shared archive directory, or be left out");
    else c.registry.archive_dir = *v;
  }
}

void read_users(const json& j, DaemonConfig& c, std::vector<std::string>& problems) {
  if (!j.is_array()) {
    problems.push_back("config.users must be an array of {name, role, password_hash, token}");
    return;
  }
  std::size_t index = 0;
  for (const json& u : j) {
    const std::string where = "config.users[" + std::to_string(index++) + "]";
    ObjectReader r(u, where, problems);
    UserEntry e;
    if (auto v = r.string("name", true)) e.name = *v;
    if (auto v = r.string("role", true)) {
      if (*v == "operator") {
        e.role = Role::Operator;
      } else if (*v != "viewer") {
        problems.push_back(where + ".role must be \"operator\" or \"viewer\"");
      }
    }
    // Only hashes: a configuration file that is read by someone else gives no password away.
    if (r.has("password")) {
      (void)r.get("password");
      problems.push_back(where + ".password: plain-text passwords are not accepted; make a hash with `imucal passwd` "
                                 "and give it as \"password_hash\"");
    }
    if (auto v = r.string("password_hash")) {
      e.password_hash = *v;
      if (!is_password_hash(*v))
        problems.push_back(where + ".password_hash is not a hash made by `imucal passwd` (it starts with $argon2id$)");
    }
    if (auto v = r.string("token")) e.token = *v;
    // Short secrets are guessable over the network.
    if (!e.token.empty() && e.token.size() < 16) problems.push_back(where + ".token must have at least 16 characters");
    if (e.name.empty() && r.has("name")) problems.push_back(where + ".name must not be empty");
    c.users.push_back(std::move(e));
  }
}

}  // namespace

void parse_listen(const std::string& text, std::string& host, std::uint16_t& port) {
  const auto colon = text.rfind(':');
  if (colon == std::string::npos || colon == 0 || colon + 1 == text.size())
    throw ConfigError("listen address '" + text + "' must be HOST:PORT, e.g. 127.0.0.1:8080");
  const std::string port_text = text.substr(colon + 1);
  std::size_t used = 0;
  long value = -1;
  try {
    value = std::stol(port_text, &used);
  } catch (const std::exception&) {
    used = 0;
  }
  if (used != port_text.size() || value < 0 || value > 65535)
    throw ConfigError("listen address '" + text + "': port must be a number from 0 to 65535");
  host = text.substr(0, colon);
  if (host.size() > 2 && host.front() == '[' && host.back() == ']') host = host.substr(1, host.size() - 2);
  port = static_cast<std::uint16_t>(value);
}

DaemonConfig parse_config(const std::string& json_text, const std::string& source) {
  json j;
  try {
    j = json::parse(json_text);
  } catch (const json::parse_error& e) {
    throw ConfigError(source + ": not valid JSON: " + e.what());
  }
  DaemonConfig c;
  std::vector<std::string> problems;
  {
    ObjectReader r(j, "config", problems);
    if (const json* v = r.get("site")) read_site(*v, c, problems);
    if (auto v = r.string("listen")) {
      try {
        parse_listen(*v, c.http.host, c.http.port);
      } catch (const ConfigError& e) {
        problems.push_back(std::string("config.listen: ") + e.what());
      }
    }
    if (auto v = r.string("data_dir")) c.data_dir = *v;
    if (auto v = r.string("limits_file")) {
      if (v->empty()) problems.push_back("config.limits_file must name a file (relative to data_dir or absolute)");
      else c.limits_file = *v;
    }
    if (const json* v = r.get("devices")) {
      if (v->is_object()) {
        c.devices = "real";
        c.device_addresses = read_device_addresses(*v, "config.devices", problems);
      } else if (v->is_string() && (*v == "sim" || *v == "sim-wire")) {
        c.devices = v->get<std::string>();
      } else {
        problems.push_back("config.devices must be \"sim\", \"sim-wire\" or an object naming the real devices "
                           "({\"table\": ..., \"chamber\": ..., \"imu\": ...}, docs/daemon.md), not " +
                           (v->is_string() ? "\"" + v->get<std::string>() + "\"" : json_type_name(*v)));
      }
    }
    if (const json* v = r.get("table")) read_table(*v, c, problems);
    if (const json* v = r.get("chamber")) read_chamber(*v, c, problems);
    if (const json* v = r.get("sim")) read_sim(*v, c, problems);
    if (const json* v = r.get("suspenders")) read_suspenders(*v, c, problems);
    if (const json* v = r.get("recorder")) read_recorder(*v, c, problems);
    if (const json* v = r.get("http")) read_http(*v, c, problems);
    if (const json* v = r.get("log")) read_log(*v, c, problems);
    if (const json* v = r.get("campaign")) {
      ObjectReader l(*v, "config.campaign", problems);
      if (auto x = l.number_in("max_duration_s", 1, 365 * 86400.0)) c.campaign.max_duration_s = *x;
      if (auto x = l.number_in("max_rate_hz", 1, 1e6)) c.campaign.max_rate_hz = *x;
    }
    if (const json* v = r.get("queue")) {
      ObjectReader q(*v, "config.queue", problems);
      if (auto x = q.boolean("autostart")) c.queue_autostart = *x;
    }
    if (auto v = r.string("operator_token")) {
      if (!v->empty() && v->size() < 16) problems.push_back("config.operator_token must have at least 16 characters");
      c.operator_token = *v;
    }
    if (const json* v = r.get("users")) read_users(*v, c, problems);
    if (const json* v = r.get("reference_equipment")) read_reference_equipment(*v, c, problems);
    if (const json* v = r.get("certificates")) read_certificates(*v, c, problems);
    if (const json* v = r.get("registry")) read_registry(*v, c, problems);
  }
  // A survey measures a g: without the measured value the site's g is normal gravity's.
  if (c.reference_equipment.gravity && !c.site.gravity_mps2)
    problems.push_back("config.reference_equipment.gravity names a gravity survey, but config.site.gravity_mps2 (the g "
                       "it measured) is not set: give the measured g, or leave the survey out");
  if (!problems.empty()) {
    std::string message = source + ": " + std::to_string(problems.size()) + " problem(s):";
    for (const auto& p : problems) message += "\n  - " + p;
    throw ConfigError(message);
  }
  return c;
}

DaemonConfig load_config_file(const std::string& path) {
  std::ifstream in(path);
  if (!in) throw ConfigError(path + ": cannot read the configuration file");
  std::stringstream text;
  text << in.rdbuf();
  DaemonConfig c = parse_config(text.str(), path);
  c.config_dir = std::filesystem::absolute(path).parent_path().string();
  return c;
}

std::optional<std::int64_t> date_day_number(const std::string& text) {
  if (text.size() != 10 || text[4] != '-' || text[7] != '-') return std::nullopt;
  for (std::size_t i : {0, 1, 2, 3, 5, 6, 8, 9})
    if (text[i] < '0' || text[i] > '9') return std::nullopt;
  int y = std::stoi(text.substr(0, 4));
  const int m = std::stoi(text.substr(5, 2)), d = std::stoi(text.substr(8, 2));
  if (m < 1 || m > 12 || d < 1) return std::nullopt;
  const bool leap = (y % 4 == 0 && y % 100 != 0) || y % 400 == 0;
  constexpr int kDays[12] = {31, 28, 31, 30, 31, 30, 31, 31, 30, 31, 30, 31};
  if (d > kDays[m - 1] + (m == 2 && leap ? 1 : 0)) return std::nullopt;
  // Howard Hinnant's days-from-civil (proleptic Gregorian calendar).
  y -= m <= 2 ? 1 : 0;
  const int era = (y >= 0 ? y : y - 399) / 400;
  const int yoe = y - era * 400;
  const int doy = (153 * (m + (m > 2 ? -3 : 9)) + 2) / 5 + d - 1;
  const int doe = yoe * 365 + yoe / 4 - yoe / 100 + doy;
  return static_cast<std::int64_t>(era) * 146097 + doe - 719468;
}

std::string date_text(std::int64_t day_number) {
  // Howard Hinnant's civil-from-days.
  const std::int64_t z = day_number + 719468;
  const std::int64_t era = (z >= 0 ? z : z - 146096) / 146097;
  const std::int64_t doe = z - era * 146097;
  const std::int64_t yoe = (doe - doe / 1460 + doe / 36524 - doe / 146096) / 365;
  const std::int64_t doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
  const std::int64_t mp = (5 * doy + 2) / 153;
  const std::int64_t d = doy - (153 * mp + 2) / 5 + 1;
  const std::int64_t m = mp < 10 ? mp + 3 : mp - 9;
  const std::int64_t y = yoe + era * 400 + (m <= 2 ? 1 : 0);
  char text[80];  // room for any 64-bit year, as the compiler counts
  std::snprintf(text, sizeof text, "%04lld-%02lld-%02lld", static_cast<long long>(y), static_cast<long long>(m),
                static_cast<long long>(d));
  return text;
}

std::string certificate_prefix(const DaemonConfig& config) {
  if (!config.certificates.prefix.empty()) return config.certificates.prefix;
  std::string out;
  for (char ch : config.site_name) {
    if (std::isalnum(static_cast<unsigned char>(ch))) out += static_cast<char>(std::toupper(static_cast<unsigned char>(ch)));
    else if (!out.empty() && out.back() != '-') out += '-';
  }
  if (out.size() > 20) out.resize(20);
  while (!out.empty() && out.back() == '-') out.pop_back();
  return out.empty() ? "IMUCAL" : out;
}

std::string registry_stand(const DaemonConfig& config) {
  if (!config.registry.stand.empty()) return config.registry.stand;
  char host[256] = {};
  if (gethostname(host, sizeof host - 1) != 0 || host[0] == '\0') return "imucald";
  return host;
}

std::string stand_url(const DaemonConfig& config, std::uint16_t port) {
  if (!config.registry.url.empty()) return config.registry.url;
  std::string host = config.http.host;
  if (host.empty() || host == "0.0.0.0" || host == "::") {
    char name[256] = {};
    host = gethostname(name, sizeof name - 1) == 0 && name[0] != '\0' ? name : "localhost";
  }
  if (host.find(':') != std::string::npos) host = "[" + host + "]";  // an IPv6 address
  return "http://" + host + ":" + std::to_string(port);
}

std::string site_path(const DaemonConfig& config, const std::string& path) {
  const std::filesystem::path file = path;
  if (file.empty() || file.is_absolute()) return file.string();
  return (std::filesystem::path(config.config_dir.empty() ? config.data_dir : config.config_dir) / file).string();
}

std::string certificate_sequence_path(const DaemonConfig& config) {
  return site_path(config, config.certificates.sequence_file.empty() ? CertificateConfig::kDefaultSequenceFile
                                                                     : config.certificates.sequence_file);
}

std::string signing_key_path(const DaemonConfig& config) { return site_path(config, config.certificates.signing_key_file); }

std::string archive_dir_path(const DaemonConfig& config) { return site_path(config, config.registry.archive_dir); }

}  // namespace imucal::daemon
