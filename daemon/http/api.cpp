#include "daemon/http/api.hpp"

#include <algorithm>
#include <cctype>
#include <cmath>
#include <filesystem>
#include <set>
#include <limits>

#include <boost/url/parse.hpp>
#include <boost/url/url_view.hpp>
#include <spdlog/spdlog.h>

#include "core/earth.hpp"
#include "core/expect_value.hpp"
#include "core/json_reader.hpp"
#include "core/number_text.hpp"
#include "core/units.hpp"
#include "daemon/analysis/analysis.hpp"
#include "daemon/analysis/model_views.hpp"
#include "daemon/analysis/run_series.hpp"
#include "daemon/campaign/campaign.hpp"
#include "daemon/config/device_config.hpp"
#include "daemon/db/csv.hpp"
#include "daemon/production/certificates.hpp"
#include "daemon/production/reference_equipment.hpp"
#include "daemon/production/test_report.hpp"
#include "daemon/production/lab.hpp"
#include "daemon/production/lab_users.hpp"
#include "daemon/production/limits_follower.hpp"
#include "daemon/production/unit_registry.hpp"
#include "daemon/registry/calibrations.hpp"
#include "daemon/subscribers/alarms.hpp"
#include "daemon/run/suspenders.hpp"
#include "daemon/subscribers/estimator_worker.hpp"
#include "motion_programs/chamber.hpp"
#include "motion_programs/program.hpp"
#include "plan/plan.hpp"
#include "plan/schema.hpp"
#include "signing/signing.hpp"

#ifndef IMUCAL_VERSION
#define IMUCAL_VERSION "0.0.0"
#endif

namespace imucal::daemon {

using nlohmann::json;

namespace {

HttpReply json_reply(int status, const json& body) {
  HttpReply r;
  r.status = status;
  r.body = json_text(body);
  r.content_type = "application/json";
  r.headers.emplace_back("Cache-Control", "no-store");
  return r;
}

HttpReply error_reply(int status, const std::string& message, json extra = json::object()) {
  extra["error"] = message;
  return json_reply(status, extra);
}

json opt_time(const std::optional<std::int64_t>& ms) { return ms ? json(iso8601_utc(*ms)) : json(nullptr); }

std::optional<std::int64_t> parse_id(const std::string& text) {
  if (text.empty() || text.size() > 18) return std::nullopt;
  for (char c : text)
    if (c < '0' || c > '9') return std::nullopt;
  return std::stoll(text);
}

// The unit a campaign names, as its campaign JSON gave it (null when it names none).
json unit_json(const CampaignRow& row) {
  if (!row.imu_serial) return nullptr;
  const json spec = json::parse(row.spec_json, nullptr, false);
  if (spec.is_object() && spec.contains("imu")) return spec.at("imu");
  return {{"serial", *row.imu_serial}, {"part_number", row.imu_part_number.value_or("")}};
}

// Whether the site's g a certificate was issued with is still the configured one (issue 35,
// deliverable 1: a corrected gravity supersedes certificates). Null when they agree, or when the
// certificate states no g; else both values and a sentence for a person. "Agree": within 1e-9
// m/s^2, a thousandth of a measured g's 1-sigma (earth::site_gravity_sigma_mps2), so that only a
// changed configuration counts, never a number's last bit after its trip through JSON.
json gravity_correction(const json& content, const DaemonConfig& config) {
  const json bench = content.is_object() ? content.value("bench", json()) : json();
  const json gravity = bench.is_object() ? bench.value("gravity", json()) : json();
  if (!gravity.is_object() || !gravity.value("value_mps2", json()).is_number()) return nullptr;
  const double issued_with = gravity.at("value_mps2").get<double>();
  const double now = earth::site_gravity_mps2(config.site);
  if (std::abs(issued_with - now) <= 1e-9) return nullptr;
  const bool configured = config.site.gravity_mps2.has_value();
  const std::string text =
      "The site's g has been corrected since this certificate was issued: its run was calibrated with g = " +
      number_text(issued_with, 9) + " m/s^2, the configuration now gives " + number_text(now, 9) + " m/s^2 (" +
      (configured ? "configured" : "WGS-84 normal gravity") +
      "). Its coefficients stand on the old value until a certificate from the recording calibrated again with the "
      "corrected g supersedes it.";
  return {{"issued_with_mps2", issued_with},
          {"now_mps2", now},
          {"source_now", configured ? "configured" : "normal_gravity"},
          {"text", text}};
}

// The certificates in force of `rows`' campaigns that state another g than the configured one.
json gravity_corrected_certificates(Registry& registry, const DaemonConfig& config, const std::vector<CampaignRow>& rows) {
  json out = json::array();
  const std::string stand = registry_stand(config);
  for (const CampaignRow& row : rows) {
    // Certificates are found by this stand's campaign ids: another stand's calibration is that
    // stand's to correct.
    if (row.stand != stand) continue;
    const auto issued = registry.current_issued(row.id);
    if (!issued) continue;
    const json correction = gravity_correction(parse_or_null(issued->content_json), config);
    if (correction.is_null()) continue;
    out.push_back({{"campaign_id", row.id}, {"number", issued->number},
                   {"issued_with_mps2", correction.at("issued_with_mps2")}, {"now_mps2", correction.at("now_mps2")}});
  }
  return out;
}

// A serial as part of a download's file name: what is not a letter, digit, '-', '_' or '.'
// becomes '_'.
std::string file_name_part(const std::string& text) {
  std::string out = text;
  for (char& c : out)
    if (!std::isalnum(static_cast<unsigned char>(c)) && c != '-' && c != '_' && c != '.') c = '_';
  return out;
}

constexpr std::size_t kAnalysisAnswersKept = 60;  // 20 campaigns' three results

json limit_or_null(double v) { return std::isfinite(v) ? json(v) : json(nullptr); }

// Whether a Content-Type names JSON (`application/json`, any case, parameters such as charset aside).
bool is_json_type(std::string_view content_type) {
  std::string media;
  for (const char c : content_type.substr(0, content_type.find(';')))
    if (c != ' ' && c != '\t') media += static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  return media == "application/json";
}

// A JSON body for a command or a login: empty means {}. Only JSON content types are accepted, so
// that a plain HTML form on another site cannot post to the API with the browser's cookie.
std::optional<HttpReply> parse_body(const ApiRequest& request, json& out) {
  if (request.body.empty()) {
    out = json::object();
    return std::nullopt;
  }
  if (!request.content_type.empty() && !is_json_type(request.content_type))
    return error_reply(415, "Content-Type must be application/json");
  try {
    out = json::parse(request.body);
  } catch (const json::exception& e) {
    // Syntax, and numbers JSON allows but a double cannot hold (1e999: out_of_range.406).
    return error_reply(400, std::string("malformed JSON: ") + e.what());
  }
  return std::nullopt;
}

// 400 for a campaign of the wrong form (validate, plan, create alike).
HttpReply malformed_campaign(const CampaignCheck& check) {
  return error_reply(400, "malformed campaign: " + (check.problems.empty() ? std::string("not a JSON object") : check.problems.front()),
                     {{"problems", check.problems}});
}

// Whether decoded URL text is UTF-8 (every string in a JSON reply must be): a percent escape may
// decode to any byte.
bool valid_utf8(std::string_view text) {
  std::size_t i = 0;
  while (i < text.size()) {
    const auto c = static_cast<unsigned char>(text[i]);
    std::size_t more = 0;
    std::uint32_t code = 0;
    if (c < 0x80) {
      ++i;
      continue;
    } else if ((c & 0xE0) == 0xC0) {
      more = 1;
      code = c & 0x1F;
    } else if ((c & 0xF0) == 0xE0) {
      more = 2;
      code = c & 0x0F;
    } else if ((c & 0xF8) == 0xF0) {
      more = 3;
      code = c & 0x07;
    } else {
      return false;
    }
    if (i + more >= text.size()) return false;  // cut short
    for (std::size_t k = 1; k <= more; ++k) {
      const auto d = static_cast<unsigned char>(text[i + k]);
      if ((d & 0xC0) != 0x80) return false;
      code = (code << 6) | (d & 0x3F);
    }
    // Overlong forms, surrogates and code points past U+10FFFF are not UTF-8.
    static constexpr std::uint32_t kMin[4] = {0, 0x80, 0x800, 0x10000};
    if (code < kMin[more] || (code >= 0xD800 && code <= 0xDFFF) || code > 0x10FFFF) return false;
    i += more + 1;
  }
  return true;
}

// The token of an `Authorization: Bearer` header, if the request has one.
std::optional<std::string_view> bearer_token(const ApiRequest& request) {
  const std::string& a = request.authorization;
  if (a.size() > 7 && (a.compare(0, 7, "Bearer ") == 0 || a.compare(0, 7, "bearer ") == 0))
    return std::string_view(a).substr(7);
  return std::nullopt;
}

// A state-changing request that the browser's session cookie authenticates must come from this
// service's own pages: a same-origin Origin when there is one, and a JSON body type (which no
// plain HTML form can send, and which makes a cross-site script's request ask first, CORS). A
// Bearer token is no ambient credential: a request carrying one is not a browser's on its own.
std::optional<HttpReply> cross_site_refusal(const ApiRequest& request) {
  if (request.method == "GET" || request.method == "HEAD") return std::nullopt;
  if (bearer_token(request) || session_from_cookie(request.cookie).empty()) return std::nullopt;
  if (!request.origin.empty() && !same_origin(request.origin, request.host))
    return error_reply(403, "cross-origin request refused: Origin '" + request.origin + "' is not this service ('" +
                                request.host + "'); a request with the session cookie must come from imucald's own pages");
  if (!is_json_type(request.content_type))
    return error_reply(415, "a " + request.method + " with the session cookie needs Content-Type: application/json" +
                                (request.content_type.empty() ? std::string(" (none given)") : " (not '" + request.content_type + "')"));
  return std::nullopt;
}

}  // namespace

bool same_origin(std::string_view origin, std::string_view host) {
  for (const std::string_view scheme : {"http://", "https://"}) {
    if (!origin.starts_with(scheme)) continue;
    std::string_view authority = origin.substr(scheme.size());
    if (authority.ends_with('/')) authority.remove_suffix(1);
    if (authority.empty() || authority.size() != host.size()) return false;
    for (std::size_t i = 0; i < host.size(); ++i)
      if (std::tolower(static_cast<unsigned char>(authority[i])) != std::tolower(static_cast<unsigned char>(host[i])))
        return false;
    return true;
  }
  return false;  // "null" (a sandboxed page, a file) or another scheme
}

std::string session_from_cookie(const std::string& cookie_header) {
  const std::string key = std::string(kSessionCookie) + "=";
  std::size_t pos = 0;
  while (pos < cookie_header.size()) {
    while (pos < cookie_header.size() && (cookie_header[pos] == ' ' || cookie_header[pos] == ';')) ++pos;
    const auto end = std::min(cookie_header.find(';', pos), cookie_header.size());
    if (cookie_header.compare(pos, key.size(), key) == 0) return cookie_header.substr(pos + key.size(), end - pos - key.size());
    pos = end + 1;
  }
  return {};
}

std::optional<Target> parse_target(const std::string& target) {
  const auto url = boost::urls::parse_origin_form(target);
  if (!url) return std::nullopt;
  Target t;
  t.path = std::string(url->encoded_path());
  for (const std::string segment : url->segments()) t.segments.push_back(segment);
  if (!t.segments.empty() && t.segments.back().empty()) t.segments.pop_back();
  for (const auto& param : url->params(boost::urls::encoding_opts(true))) t.query[param.key] = param.value;
  // Decoded text goes into replies (an id, a serial in a message): it must be UTF-8.
  if (!std::all_of(t.segments.begin(), t.segments.end(), valid_utf8)) return std::nullopt;
  for (const auto& [key, value] : t.query)
    if (!valid_utf8(key) || !valid_utf8(value)) return std::nullopt;
  return t;
}

namespace {

// The chamber controller's register map and whether a maker's manual vouches for it (null on the
// in-process simulation): an address nobody checked is worth a look before a chamber is trusted
// overnight.
json chamber_map_json(const DaemonConfig& config) {
  std::optional<drivers::RegisterMap> map;
  if (config.device_addresses) map = config.device_addresses->chamber.map;
  else if (config.devices == "sim-wire") map = drivers::load_register_map(kSimWireChamberMap);
  if (!map) return nullptr;
  const auto unchecked = map->source.unchecked_keys();
  return {{"name", map->name},
          {"checked", unchecked.empty() ? "yes" : unchecked.size() == map->source.registers.size() ? "no" : "partly"},
          {"summary", map->source.summary()},
          {"unchecked", unchecked}};
}

// The table controller's dialect (null on the in-process simulation): which language the driver
// speaks and what it was written from.
json table_dialect_json(const DaemonConfig& config) {
  if (config.device_addresses) {
    const auto& t = config.device_addresses->table;
    return {{"name", t.dialect.name}, {"configured", t.dialect_name}, {"source", t.dialect.source}};
  }
  if (config.devices != "sim-wire") return nullptr;
  const auto& d = drivers::dialect::imucal_acl();
  return {{"name", d.name}, {"configured", d.name}, {"source", d.source}};
}

}  // namespace

Api::Api(const DaemonConfig& config, DaemonDb& db, Registry& registry, Sequencer& sequencer, Auth& auth,
         const AuditTrail& audit, CertificateIssuer& certificates)
    : config_(config),
      db_(db),
      registry_(registry),
      sequencer_(sequencer),
      auth_(auth),
      audit_(audit),
      certificates_(certificates),
      // The limits go by their file's name on a stand alone, by the lab's registry on PostgreSQL.
      limits_(registry, registry.backend() == "sqlite" ? std::filesystem::path(config.limits_file).filename().string()
                                                       : std::string("the lab's registry")),
      programs_(json::array()),
      started_ms_(now_unix_ms()),
      started_(std::chrono::steady_clock::now()) {
  // Two threads: one long analysis (a 12 h thermal run) does not hold up every other.
  // The listener is called under its mutex, so that once set_event_listener({}) has returned no
  // job is still inside it (the HTTP server it points to may then go).
  jobs_ = std::make_unique<AnalysisJobs>(2, kAnalysisAnswersKept, [this](const json& e) { broadcast(e); },
                                         static_cast<std::size_t>(config.http.max_analysis_jobs));
  chamber_map_ = chamber_map_json(config);
  table_dialect_ = table_dialect_json(config);
  // The truths a simulated campaign may name, for the builder's choice (docs/api.md).
  truths_ = json::array();
  for (const NamedTruth& t : named_truths(config))
    truths_.push_back({{"name", t.name}, {"description", t.description}, {"builtin", t.builtin}});
  // Each built-in program, and the built-in campaign `full`, as the campaign check sees it: its
  // joined program, duration, segments, and the estimators a campaign of it runs by default (the
  // builder offers those, so the rule lives in one place: check_campaign).
  std::vector<std::string> names = motion::builtin_program_names();
  names.push_back("full");
  for (const auto& name : names) {
    const CampaignCheck check = check_campaign({{"name", name}, {"program", name}}, config);
    if (!check.spec) {
      std::string why;
      for (const auto& p : check.problems) why += (why.empty() ? "" : "; ") + p;
      spdlog::warn("built-in program '{}' does not pass the campaign check with the configured limits: {}", name, why);
      continue;
    }
    json segments = json::array();
    for (const auto& s : check.segments)
      segments.push_back({{"name", s.name}, {"kind", s.kind}, {"t0_s", s.t0_s}, {"t1_s", s.t1_s}});
    json program = json::parse(check.spec->program_json);
    if (name == "full")
      program["comment"] = "The whole method in one run: direct, lever-arm, navigation and evaluate, each stage from "
                           "the models before, the Schuler test of every stage's model.";
    json entry = {{"name", name},
                  {"duration_s", check.duration_s},
                  {"segments", segments},
                  {"program", program},
                  {"estimators", check.spec->estimators}};
    // The built-in thermal campaigns bring their chamber profile: the builder shows its steps.
    if (motion::is_builtin_chamber(name)) entry["chamber"] = check.spec->normalized.at("chamber");
    programs_.push_back(std::move(entry));
  }
}

std::optional<Principal> Api::authenticate(const ApiRequest& request, bool allow_query_token) {
  if (const auto token = bearer_token(request)) return auth_.from_token(*token);
  if (const std::string sid = session_from_cookie(request.cookie); !sid.empty()) {
    if (auto p = auth_.from_session(sid)) return p;
  }
  if (allow_query_token) {
    if (const auto t = parse_target(request.target)) {
      const auto it = t->query.find("token");
      if (it != t->query.end()) return auth_.from_token(it->second);
    }
  }
  return std::nullopt;
}

json Api::status() {
  json limits_table = json::object();
  for (std::size_t a = 0; a < 3; ++a) {
    const auto& l = config_.table_limits.axis[a];
    limits_table[motion::kAxisNames[a]] = {{"min_deg", limit_or_null(l.min_deg)}, {"max_deg", limit_or_null(l.max_deg)},
                                           {"rate_dps", l.rate_dps}, {"accel_dps2", l.accel_dps2}};
  }
  json active = nullptr;
  if (const auto id = sequencer_.active_id()) {
    if (const auto row = db_.campaign(*id)) active = {{"id", row->id}, {"name", row->name}, {"state", to_string(row->state)}};
  }
  // The data directory's file system: a full disk suspends runs and refuses changes (503) while
  // the writes the daemon must make wait in memory.
  std::error_code ec;
  const auto space = std::filesystem::space(config_.data_dir, ec);
  const json storage = {{"free_bytes", ec ? json() : json(space.available)},
                        {"deferred_writes", sequencer_.deferred_writes()}};
  return {{"service", "imucald"},
          {"version", IMUCAL_VERSION},
          {"storage", storage},
          // A lab's registry server away: its writes wait on this stand's disk (journaled_registry.hpp).
          {"registry", {{"backend", registry_.backend()}, {"reachable", registry_.reachable()},
                        {"pending_writes", registry_.pending_writes()}}},
          {"chamber_map", chamber_map_},
          {"table_dialect", table_dialect_},
          {"started", iso8601_utc(started_ms_)},
          {"uptime_s", std::chrono::duration<double>(std::chrono::steady_clock::now() - started_).count()},
          {"devices", config_.devices},
          {"site", site_json(config_)},
          {"active", active},
          {"queue", db_.queue()},
          // Judged today (UTC): the live page warns of an instrument due within a week or overdue.
          {"reference_equipment", reference_equipment_json(config_, utc_day(now_unix_ms()), true)},
          {"limits",
           {{"table", limits_table},
            {"chamber", {{"min_C", config_.chamber.limits.min_C}, {"max_C", config_.chamber.limits.max_C},
                         {"max_ramp_C_per_min", config_.chamber.limits.max_ramp_C_per_min},
                         {"safe_setpoint_C", config_.chamber.safe_setpoint_C},
                         {"tolerance_C", config_.chamber.tolerance_C}}},
            {"campaign", {{"max_duration_s", config_.campaign.max_duration_s},
                          {"max_rate_hz", config_.campaign.max_rate_hz},
                          {"estimators", known_estimators()}, {"truths", truths_},
                          {"default_truth", config_.sim.truth}}}}}};
}

// One endpoint. A pattern's segments are literal, or a placeholder: {id} a campaign id (a
// segment that is not one answers 404 "no campaign"), {command} a run command (a segment that is
// not one does not match), {alarm}, {serial} and {number} any segment. Where patterns of several
// specificities match a path, the one with the most literal segments wins (/api/campaigns/1/model
// is the model, not a command). GET routes answer HEAD too.
struct Call {
  const ApiRequest& request;
  const Target& target;
  const std::vector<std::string>& args;  // the placeholders' segments, in order
  std::int64_t id = 0;                   // {id}
  const Principal* who = nullptr;        // null on open routes
};

struct Api::Route {
  enum class Access { open, viewer, operator_ };  // operator_: changes something
  const char* method;
  const char* pattern;
  Access access;
  std::function<HttpReply(Api&, const Call&)> handle;
};

namespace {

std::vector<std::string_view> pattern_segments(std::string_view pattern) {
  std::vector<std::string_view> out;
  while (!pattern.empty()) {
    pattern.remove_prefix(1);  // '/'
    const auto end = std::min(pattern.find('/'), pattern.size());
    out.push_back(pattern.substr(0, end));
    pattern.remove_prefix(end);
  }
  return out;
}

// A route whose pattern matches a path: the placeholders' segments, and how many of the
// pattern's segments are literal (the most specific match wins).
struct Matched {
  const Api::Route* route = nullptr;
  std::vector<std::string> args;
  int literal = 0;
};

std::optional<Matched> match_route(const Api::Route& route, const std::vector<std::string>& segments) {
  const std::string_view pattern = route.pattern;
  const auto parts = pattern_segments(pattern);
  if (parts.size() != segments.size()) return std::nullopt;
  std::vector<std::string> args;
  int literal = 0;
  for (std::size_t i = 0; i < parts.size(); ++i) {
    if (parts[i].starts_with('{')) {
      if (parts[i] == "{command}" && !parse_command(segments[i])) return std::nullopt;
      args.push_back(segments[i]);
    } else if (parts[i] == segments[i]) {
      ++literal;
    } else {
      return std::nullopt;
    }
  }
  return Matched{&route, std::move(args), literal};
}

}  // namespace

// The route table: one row per route of docs/api.md.
// function-size: a table of data
const std::vector<Api::Route>& Api::routes() {
  using A = Route::Access;
  static const std::vector<Route> table = {
      {"POST", "/api/login", A::open, [](Api& a, const Call& c) { return a.login(c.request); }},
      {"POST", "/api/logout", A::open, [](Api& a, const Call& c) { return a.logout(c.request); }},
      // For monitoring and systemd: no authentication, no details (whoever can reach the port may ask).
      {"GET", "/api/health", A::open,
       [](Api& a, const Call&) {
         if (a.shutting_down_) return json_reply(503, {{"status", "shutting down"}});
         return json_reply(200, {{"status", "ok"}});
       }},
      {"GET", "/api/me", A::viewer,
       [](Api&, const Call& c) {
         return json_reply(200, {{"user", c.who->user}, {"role", to_string(c.who->role)}, {"via", c.who->via}});
       }},
      {"GET", "/api/status", A::viewer, [](Api& a, const Call&) { return json_reply(200, a.status()); }},
      // The lab overview (issue 38): every stand of the registry, what it runs, its alarms.
      {"GET", "/api/lab", A::viewer,
       [](Api& a, const Call&) {
         return json_reply(200, lab_json(a.registry_.stands(), now_unix_ms(), registry_stand(a.config_)));
       }},
      {"GET", "/api/programs", A::viewer, [](Api& a, const Call&) { return json_reply(200, {{"programs", a.programs_}}); }},
      // The coefficients' names, groups, units and the seed's targets, from the tables that own them
      // (plan/schema.hpp): the browser keeps no copy.
      {"GET", "/api/schema", A::viewer, [](Api&, const Call&) { return json_reply(200, plan::schema_json()); }},
      // The conditions that hold a run, with the daemon's settings (a campaign may set its own:
      // `suspenders` in its JSON).
      {"GET", "/api/suspenders", A::viewer,
       [](Api& a, const Call&) {
         const auto& s = a.config_.suspenders;
         return json_reply(200, {{"suspenders", Suspenders(s).describe()},
                                 {"settings",
                                  {{"settle_s", s.settle_s},
                                   {"frame_timeout_s", s.frame_timeout_s},
                                   {"chamber_persist_s", s.chamber_persist_s}}}});
       }},
      // Reads with a body: a viewer may ask.
      {"POST", "/api/campaigns/validate", A::viewer, [](Api& a, const Call& c) { return a.validate_campaign(c.request); }},
      {"POST", "/api/campaigns/plan", A::viewer, [](Api& a, const Call& c) { return a.plan_campaign(c.request); }},
      {"GET", "/api/campaigns", A::viewer, [](Api& a, const Call& c) { return a.list_campaigns(c.target.query); }},
      {"POST", "/api/campaigns", A::operator_, [](Api& a, const Call& c) { return a.create_campaign(c.request); }},
      {"GET", "/api/limits", A::viewer,
       [](Api& a, const Call&) {
         json doc = a.limits_.document();
         doc["source"] = a.limits_.current().source;
         return json_reply(200, doc);
       }},
      {"PUT", "/api/limits", A::operator_, [](Api& a, const Call& c) { return a.replace_limits(c.request, *c.who); }},
      {"GET", "/api/users", A::operator_,
       [](Api& a, const Call&) { return json_reply(200, users_json(a.config_.users, a.registry_.users())); }},
      {"PUT", "/api/users/{user}", A::operator_,
       [](Api& a, const Call& c) { return a.put_lab_user(c.args[0], c.request, *c.who); }},
      {"DELETE", "/api/users/{user}", A::operator_,
       [](Api& a, const Call& c) { return a.remove_lab_user(c.args[0], *c.who); }},
      {"GET", "/api/compare", A::viewer, [](Api& a, const Call& c) { return a.compare_campaigns(c.target.query); }},
      {"GET", "/api/alarms", A::viewer, [](Api& a, const Call& c) { return a.list_alarms(c.target.query); }},
      {"GET", "/api/audit", A::viewer, [](Api& a, const Call& c) { return a.list_audit(c.target.query); }},
      {"POST", "/api/alarms/{alarm}/ack", A::operator_,
       [](Api& a, const Call& c) { return a.acknowledge_alarm(c.args[0], *c.who); }},
      {"GET", "/api/imus", A::viewer,
       [](Api& a, const Call&) {
         return json_reply(200, unit_list_json(a.registry_.unit_campaigns(std::nullopt), a.limits_.current()));
       }},
      {"GET", "/api/imus/{serial}", A::viewer,
       [](Api& a, const Call& c) {
         const auto rows = a.registry_.unit_campaigns(c.args[0]);
         if (rows.empty()) return error_reply(404, "no campaign names the unit '" + c.args[0] + "'");
         json out = unit_detail_json(c.args[0], rows, a.limits_.current());
         out["gravity_corrected"] = gravity_corrected_certificates(a.registry_, a.config_, rows);
         add_calibration_links(out, registry_stand(a.config_), a.registry_.stands(), archive_dir_path(a.config_));
         return json_reply(200, out);
       }},
      {"GET", "/api/archive/{stand}/{campaign}/recording", A::viewer,
       [](Api& a, const Call& c) { return a.archived_recording_reply(c.args[0], c.args[1]); }},
      {"GET", "/api/imus/{serial}/history.csv", A::viewer,
       [](Api& a, const Call& c) {
         const auto rows = a.registry_.unit_campaigns(c.args[0]);
         if (rows.empty()) return error_reply(404, "no campaign names the unit '" + c.args[0] + "'");
         HttpReply r;
         r.body = unit_history_csv(rows);
         r.content_type = "text/csv; charset=utf-8";
         r.headers.emplace_back("Cache-Control", "no-store");
         r.headers.emplace_back("Content-Disposition",
                                "attachment; filename=\"imu-" + file_name_part(c.args[0]) + "-history.csv\"");
         return r;
       }},
      {"GET", "/api/campaigns/{id}", A::viewer, [](Api& a, const Call& c) { return a.campaign_detail(c.id); }},
      {"GET", "/api/campaigns/{id}/model", A::viewer,
       [](Api& a, const Call& c) { return a.campaign_model(c.id, c.target.query); }},
      {"GET", "/api/campaigns/{id}/truth", A::viewer, [](Api& a, const Call& c) { return a.campaign_truth(c.id); }},
      {"GET", "/api/campaigns/{id}/progress", A::viewer, [](Api& a, const Call& c) { return a.campaign_progress(c.id); }},
      {"GET", "/api/campaigns/{id}/recording", A::viewer,
       [](Api& a, const Call& c) { return a.campaign_recording(c.id); }},
      {"GET", "/api/campaigns/{id}/series", A::viewer,
       [](Api& a, const Call& c) { return a.campaign_series(c.id, c.target.query); }},
      {"GET", "/api/campaigns/{id}/allan", A::viewer, [](Api& a, const Call& c) { return a.campaign_analysis(c.id, "allan"); }},
      {"GET", "/api/campaigns/{id}/thermal", A::viewer,
       [](Api& a, const Call& c) { return a.campaign_analysis(c.id, "thermal"); }},
      {"GET", "/api/campaigns/{id}/evaluation", A::viewer,
       [](Api& a, const Call& c) { return a.campaign_analysis(c.id, "evaluation"); }},
      {"GET", "/api/campaigns/{id}/events.csv", A::viewer, [](Api& a, const Call& c) { return a.campaign_events_csv(c.id); }},
      {"GET", "/api/campaigns/{id}/certificate", A::viewer,
       [](Api& a, const Call& c) { return a.campaign_certificate(c.id); }},
      {"GET", "/api/campaigns/{id}/report", A::viewer, [](Api& a, const Call& c) { return a.campaign_report(c.id, c.target.query); }},
      {"GET", "/api/certificates/{number}", A::viewer,
       [](Api& a, const Call& c) { return a.certificate_by_number(c.args[0]); }},
      {"GET", "/api/certificates/{number}/page", A::viewer,
       [](Api& a, const Call& c) { return a.certificate_page(c.args[0]); }},
      {"PUT", "/api/certificates/{number}/page", A::operator_,
       [](Api& a, const Call& c) { return a.store_certificate_page(c.args[0], c.request, *c.who); }},
      {"POST", "/api/campaigns/{id}/accept", A::operator_,
       [](Api& a, const Call& c) { return a.campaign_accept(c.id, c.request, *c.who); }},
      {"POST", "/api/campaigns/{id}/recalibrate", A::operator_,
       [](Api& a, const Call& c) { return a.campaign_recalibrate(c.id, c.request, *c.who); }},
      {"POST", "/api/campaigns/{id}/prompt", A::operator_,
       [](Api& a, const Call& c) { return a.campaign_prompt(c.id, c.request, *c.who); }},
      {"POST", "/api/campaigns/{id}/{command}", A::operator_,
       [](Api& a, const Call& c) { return a.campaign_command(c.id, c.args[1], c.request, *c.who); }},
  };
  return table;
}

HttpReply Api::handle(const ApiRequest& request) {
  const auto target = parse_target(request.target);
  if (!target)
    return error_reply(400, "malformed URL: a bad percent escape, or text that is not UTF-8 once decoded");
  if (auto refused = cross_site_refusal(request)) return *refused;
  const std::string& path = target->path;
  const std::string& method = request.method;
  try {
    // The routes of this path (the most specific pattern), then the one of this method.
    std::vector<Matched> on_path;
    for (const Route& r : routes()) {
      auto m = match_route(r, target->segments);
      if (!m || (!on_path.empty() && m->literal < on_path.front().literal)) continue;
      if (!on_path.empty() && m->literal > on_path.front().literal) on_path.clear();
      on_path.push_back(std::move(*m));
    }
    const bool open = !on_path.empty() && std::all_of(on_path.begin(), on_path.end(), [](const Matched& m) {
      return m.route->access == Route::Access::open;
    });
    std::optional<Principal> who;
    if (!open) {
      who = authenticate(request, false);
      if (!who) {
        HttpReply r = error_reply(401, "authentication required");
        r.headers.emplace_back("WWW-Authenticate", "Bearer realm=\"imucald\"");
        return r;
      }
    }
    if (on_path.empty()) return error_reply(404, "no such endpoint: " + path);
    const Matched* chosen = nullptr;
    std::string allow;
    for (const Matched& m : on_path) {
      allow += (allow.empty() ? "" : ", ") + std::string(m.route->method);
      if (method == m.route->method || (method == "HEAD" && std::string_view(m.route->method) == "GET")) chosen = &m;
    }
    // Every other method changes something: an operator's, and not while shutting down. A read
    // marked the operator's (the lab's accounts) is one too.
    const bool operators_route = chosen && chosen->route->access == Route::Access::operator_;
    const bool reads = (method == "GET" || method == "HEAD") ? !operators_route : chosen && !operators_route;
    if (!open && !reads && (!who || who->role != Role::Operator)) return error_reply(403, "operator role required");
    if (!open && !reads && shutting_down_) return error_reply(503, "the daemon is shutting down");
    if (!chosen) {
      HttpReply r = error_reply(405, method + " is not allowed on " + path);
      r.headers.emplace_back("Allow", allow);
      return r;
    }
    const Route& route = *chosen->route;
    Call call{request, *target, chosen->args};
    call.who = who ? &*who : nullptr;
    if (std::string_view(route.pattern).find("{id}") != std::string_view::npos) {
      const auto id = parse_id(call.args.front());
      if (!id) return error_reply(404, "no campaign '" + call.args.front() + "'");
      call.id = *id;
    }
    return route.handle(*this, call);
  } catch (const json::exception& e) {
    // A value of the wrong type or range where a handler read the client's JSON: the client's
    // problem, whichever handler met it (one place, not a check in each).
    spdlog::warn("{} {}: refused: {}", method, path, e.what());
    return error_reply(400, std::string("malformed request: ") + e.what());
  } catch (const std::invalid_argument& e) {
    spdlog::warn("{} {}: refused: {}", method, path, e.what());
    return error_reply(400, std::string("malformed request: ") + e.what());
  } catch (const std::exception& e) {
    spdlog::error("{} {}: {}", method, path, e.what());
    // The daemon's database on a full disk (or failing, or locked too long): the request may be
    // repeated once it is writable again; the service goes on.
    if (bool damaged = false; is_database_failure(e, &damaged) && !damaged)
      return error_reply(503, std::string("the daemon's storage cannot take this now, try again later: ") + e.what());
    return error_reply(500, std::string("internal error: ") + e.what());
  }
}

HttpReply Api::login(const ApiRequest& request) {
  json body;
  if (auto bad = parse_body(request, body)) return *bad;
  std::vector<std::string> problems;
  std::optional<std::string> user, password, token;
  {
    ObjectReader r(body, "body", problems);
    user = r.string("user");
    password = r.string("password");
    token = r.string("token");
  }
  if (!problems.empty()) return error_reply(400, problems.front(), {{"problems", problems}});
  Auth::Login l;
  if (token) {
    l = auth_.login_token(*token, request.client);
  } else if (user && password) {
    l = auth_.login_password(*user, *password, request.client);
  } else {
    const std::string why = "body must hold {\"user\", \"password\"} or {\"token\"}";
    return error_reply(400, why, {{"problems", json::array({why})}});
  }
  if (l.status != 200) return error_reply(l.status, l.error);
  HttpReply r = json_reply(200, {{"user", l.principal.user}, {"role", to_string(l.principal.role)},
                                 {"idle_timeout_s", auth_.idle_timeout_s()}});
  r.headers.emplace_back("Set-Cookie", std::string(kSessionCookie) + "=" + l.session_id +
                                           "; HttpOnly; SameSite=Strict; Path=/");
  spdlog::info("sign-in: {} ({})", l.principal.user, to_string(l.principal.role));
  return r;
}

HttpReply Api::logout(const ApiRequest& request) {
  const std::string sid = session_from_cookie(request.cookie);
  if (!sid.empty()) auth_.logout(sid);
  HttpReply r = json_reply(200, {{"ok", true}});
  r.headers.emplace_back("Set-Cookie", std::string(kSessionCookie) + "=; HttpOnly; SameSite=Strict; Path=/; Max-Age=0");
  return r;
}

json Api::summary(const CampaignRow& row) {
  const double progress = row.duration_s > 0 ? std::clamp(row.program_time_s / row.duration_s, 0.0, 1.0) : 0.0;
  return {{"id", row.id},
          {"name", row.name},
          {"state", to_string(row.state)},
          {"program", row.program_label},
          {"created", iso8601_utc(row.created_ms)},
          {"started", opt_time(row.started_ms)},
          {"ended", opt_time(row.ended_ms)},
          {"duration_s", row.duration_s},
          {"program_time_s", row.program_time_s},
          {"progress", progress},
          {"queue_position", row.queue_position ? json(*row.queue_position) : json(nullptr)},
          {"has_model", row.model_json.has_value()},
          {"error", row.error ? json(*row.error) : json(nullptr)},
          {"imu", unit_json(row)},
          {"complete", row.complete.value_or(false)},
          {"accepted", completeness_json(row).at("accepted")}};
}

namespace {

// The body {"reason": TEXT} of an operator's decision that must say why (`why`: what it must say):
// 400 naming what is wrong, or none with `reason` set.
std::optional<HttpReply> read_reason(const ApiRequest& request, const std::string& why, std::string& reason) {
  json body;
  if (auto bad = parse_body(request, body)) return bad;
  std::vector<std::string> problems;
  std::optional<std::string> text;
  {
    ObjectReader r(body, "body", problems);
    text = r.string("reason", true);
  }
  if (!problems.empty()) return error_reply(400, problems.front(), {{"problems", problems}});
  // (A missing reason is a problem above already.)
  if (!text || text->find_first_not_of(" \t\r\n") == std::string::npos) {
    const std::string what = "body.reason must say " + why;
    return error_reply(400, what, {{"problems", json::array({what})}});
  }
  reason = *text;
  return std::nullopt;
}

}  // namespace

void Api::record_calibration(std::int64_t id) {
  // The change is made and audited: a registry that cannot take the row now is logged, and the
  // row is recorded again at the campaign's next change.
  try {
    (void)record_unit_calibration(db_, registry_, id);
  } catch (const std::exception& e) {
    spdlog::error("campaign {}: its calibration could not be recorded in the registry: {}", id, e.what());
  }
}

HttpReply Api::campaign_accept(std::int64_t id, const ApiRequest& request, const Principal& who) {
  std::string reason;
  if (auto bad = read_reason(request, "why the partial run is accepted", reason)) return *bad;
  const auto row = db_.campaign(id);
  if (!row) return error_reply(404, "no campaign " + std::to_string(id));
  if (const std::string why = cannot_accept(*row); !why.empty())
    return error_reply(409, "campaign " + std::to_string(id) + " cannot be accepted: " + why);
  db_.accept(id, reason, who.user);
  spdlog::info("campaign {}: partial run accepted by {}: {}", id, who.user, reason);
  record_calibration(id);
  audit_.append(who.user, "campaign.accepted", "campaign " + std::to_string(id), {{"reason", reason}, {"state", to_string(row->state)}});
  try {
    certificates_.issue(id, "partial run accepted by " + who.user + ": " + reason);
  } catch (const std::exception& e) {
    spdlog::error("campaign {}: accepted, but no certificate yet: {}", id, e.what());
  }
  return json_reply(200, summary(expect_value(db_.campaign(id), "the campaign just accepted")));
}

HttpReply Api::campaign_recalibrate(std::int64_t id, const ApiRequest& request, const Principal& who) {
  std::string reason;
  if (auto bad = read_reason(request, "why the run is calibrated again", reason)) return *bad;
  const double g_now = earth::site_gravity_mps2(config_.site);
  AnalysisJobs::Key key;
  key.campaign = id;
  key.analysis = "recalibration";
  key.state = "g = " + number_text(g_now, 9);
  // Asked again: its answer, although the certificate it superseded no longer calls for it.
  if (const auto asked = jobs_->find(key)) return job_reply(*asked);
  const std::string name = "campaign " + std::to_string(id);
  const auto row = db_.campaign(id);
  if (!row) return error_reply(404, "no " + name);
  const auto current = registry_.current_issued(id);
  if (!current) return error_reply(409, name + " has no certificate to supersede");
  const json correction = gravity_correction(parse_or_null(current->content_json), config_);
  if (correction.is_null())
    return error_reply(409, name + "'s certificate " + current->number + " states the site's g as configured (" +
                                number_text(g_now, 9) + " m/s^2): there is nothing to calibrate again");
  if (auto none = no_recording(*row, name + " cannot be calibrated again: ")) return *none;
  const CampaignCheck check = check_campaign_text(row->spec_json, config_);
  if (!check.spec)
    return error_reply(409, name + "'s campaign no longer passes its checks: " +
                                (check.problems.empty() ? std::string("malformed") : check.problems.front()));
  EstimatorWorker::Spec spec;
  try {
    spec = estimator_spec(*check.spec, db_);
  } catch (const std::runtime_error& e) {
    return error_reply(409, name + " cannot be calibrated again: " + e.what());
  }
  const double g_before = correction.at("issued_with_mps2").get<double>();
  auto compute = [this, id, user = who.user, reason, spec, g_before, path = run_path(*row),
                  g_configured = config_.site.gravity_mps2](const AnalysisJobs::Progress& progress) -> std::pair<int, json> {
    Recalibration r;
    try {
      r = calibrate_again(path, spec.estimators, spec.start_model, g_configured, progress);
    } catch (const NotAvailable& e) {
      return {409, {{"error", e.what()}}};
    }
    if (!r.model)
      return {422, {{"error", "calibrated again with the corrected g, no calibration stage was done; the certificate in "
                              "force stands"},
                    {"results", r.results}}};
    try {
      return {200, recalibrated(id, user, reason, r, g_before)};
    } catch (const std::exception& e) {
      return {503, {{"error", "calibrated again, but not stored (" + std::string(e.what()) +
                                  "); the certificate in force stands: ask again"}}};
    }
  };
  return job_reply(jobs_->request(key, std::move(compute)));
}

json Api::recalibrated(std::int64_t id, const std::string& who, const std::string& reason, const Recalibration& r,
                       double g_before_mps2) {
  const std::string name = "campaign " + std::to_string(id);
  const double g_now = earth::site_gravity_mps2(config_.site);
  std::string superseded;
  // Stored under the issuer's lock: no other issue reads the run half stored.
  const IssuedCertificateRow c = certificates_.reissue_recalibrated(id, [&](const IssuedCertificateRow& current) {
    superseded = current.number;
    const CampaignRow before = expect_value(db_.campaign(id), "the campaign calibrated again");
    // The stages calibrated again replace their results; the others (the navigation display) stay.
    json results = parse_or_null(before.results_json);
    if (!results.is_object()) results = json::object();
    for (const auto& [estimator, report] : r.results.items()) results[estimator] = report;
    db_.set_model(id, imu_model_to_json_text(expect_value(r.model, "the recalibrated model")));
    db_.set_results(id, results.dump());
    audit_.append(who, "campaign.recalibrated", name,
                  {{"reason", reason}, {"gravity_before_mps2", g_before_mps2}, {"gravity_after_mps2", g_now},
                   {"certificate", current.number}});
    return "calibrated again from its recording by " + who + " with the corrected site g = " + number_text(g_now, 9) +
           " m/s^2 (was " + number_text(g_before_mps2, 9) + "): " + reason;
  });
  spdlog::info("{}: calibrated again with g = {} m/s^2 by {}; certificate {} supersedes {}", name, number_text(g_now, 9),
               who, c.number, superseded);
  record_calibration(id);  // its new model in the unit's history
  return {{"campaign", id}, {"certificate", issued_json(c)}, {"superseded", superseded}};
}

HttpReply Api::list_campaigns(const std::map<std::string, std::string>& query) {
  std::int64_t limit = 100;
  if (const auto it = query.find("limit"); it != query.end()) {
    const auto v = parse_id(it->second);
    if (!v || *v < 1 || *v > 10000) return error_reply(400, "limit must be a number from 1 to 10000");
    limit = *v;
  }
  json list = json::array();
  for (const auto& row : db_.campaigns(limit)) list.push_back(summary(row));
  return json_reply(200, {{"campaigns", list}});
}

HttpReply Api::validate_campaign(const ApiRequest& request) {
  json body;
  if (auto bad = parse_body(request, body)) return *bad;
  const CampaignCheck check = check_campaign(body, config_);
  // Not a campaign at all, or one naming a path: refused as for creation, not judged.
  if (check.malformed) return malformed_campaign(check);
  json segments = json::array();
  for (const auto& s : check.segments)
    segments.push_back({{"name", s.name}, {"kind", s.kind}, {"t0_s", s.t0_s}, {"t1_s", s.t1_s}});
  return json_reply(200, {{"valid", check.problems.empty()},
                          {"problems", check.problems},
                          {"duration_s", check.duration_s},
                          {"segments", segments}});
}

HttpReply Api::create_campaign(const ApiRequest& request) {
  json body;
  if (auto bad = parse_body(request, body)) return *bad;
  const CampaignCheck check = check_campaign(body, config_);
  if (check.malformed) return malformed_campaign(check);
  if (!check.spec) return error_reply(422, "campaign is invalid", {{"problems", check.problems}});
  const CampaignSpec& spec = *check.spec;
  const auto who = authenticate(request, false);
  const std::int64_t id = store_campaign(db_, check, "posted by " + (who ? who->user : std::string("?")));
  spdlog::info("campaign {} '{}' posted ({}, {:.1f} s)", id, spec.name, spec.program_label, check.duration_s);
  audit_.append(who ? who->user : std::string("?"), "campaign.created", "campaign " + std::to_string(id),
        {{"name", spec.name}, {"program", spec.program_label}, {"duration_s", check.duration_s}});
  HttpReply r = json_reply(201, {{"id", id}, {"state", "created"}, {"duration_s", check.duration_s}});
  r.headers.emplace_back("Location", "/api/campaigns/" + std::to_string(id));
  return r;
}

HttpReply Api::replace_limits(const ApiRequest& request, const Principal& who) {
  json body;
  if (auto bad = parse_body(request, body)) return *bad;
  if (!body.is_object()) return error_reply(400, "the limits must be a JSON object {\"format\": \"imucal-limits/1\", ...}");
  body.erase("source");  // what GET adds, so a GET's reply can be edited and put back
  json doc;
  try {
    doc = imucal::daemon::replace_limits(limits_, audit_, registry_, db_, certificates_, body, who.user);
  } catch (const std::invalid_argument& e) {
    return error_reply(400, e.what());
  } catch (const std::exception& e) {
    return error_reply(500, std::string("the limits were not saved: ") + e.what());
  }
  doc["source"] = limits_.current().source;
  return json_reply(200, doc);
}

// The lab's accounts (production/lab_users.hpp): put in the registry, every stand signs them in.
HttpReply Api::put_lab_user(const std::string& name, const ApiRequest& request, const Principal& who) {
  json body;
  if (auto bad = parse_body(request, body)) return *bad;
  if (std::any_of(config_.users.begin(), config_.users.end(), [&](const UserEntry& u) { return u.name == name; }))
    return error_reply(409, "'" + name + "' is a user of this stand's configuration, which wins over a lab account; "
                            "choose another name or remove it from the configuration");
  UserRow row;
  try {
    row = lab_user_from_request(name, body, who.user, now_unix_ms());
  } catch (const std::invalid_argument& e) {
    return error_reply(400, e.what());
  }
  registry_.put_user(row);
  audit_.append(who.user, "user.put", "user " + name, {{"role", row.role}});
  return json_reply(200, {{"name", row.name}, {"role", row.role}, {"changed", iso8601_utc(row.changed_ms)},
                          {"changed_by", row.changed_by}});
}

HttpReply Api::remove_lab_user(const std::string& name, const Principal& who) {
  if (!registry_.remove_user(name)) return error_reply(404, "the lab's registry has no account '" + name + "'");
  audit_.append(who.user, "user.removed", "user " + name, json::object());
  return json_reply(200, {{"removed", name}});
}

namespace {

// One campaign of a comparison, named by the query's `key` ("a" or "b"): its row and its model,
// or the reply that refuses it.
std::optional<HttpReply> comparison_side(DaemonDb& db, const std::map<std::string, std::string>& query, const char* key,
                                         CampaignRow& row, json& model) {
  const auto it = query.find(key);
  const auto id = it == query.end() ? std::nullopt : parse_id(it->second);
  if (!id) return error_reply(400, std::string("query ") + key + " must be a campaign id (/api/compare?a=ID&b=ID)");
  auto found = db.campaign(*id);
  if (!found) return error_reply(404, "no campaign " + std::to_string(*id));
  if (!found->model_json) return error_reply(409, "campaign " + std::to_string(*id) + " has no model to compare");
  model = parse_or_null(*found->model_json);
  row = std::move(*found);
  return std::nullopt;
}

}  // namespace

HttpReply Api::compare_campaigns(const std::map<std::string, std::string>& query) {
  CampaignRow rows[2];
  json models[2];
  const char* names[2] = {"a", "b"};
  for (int i = 0; i < 2; ++i)
    if (auto refused = comparison_side(db_, query, names[i], rows[i], models[i])) return *refused;
  // Misalignments of an instrument-frame model and a body-frame one are different angles.
  if (models[0].value("frame", std::string("instrument")) != models[1].value("frame", std::string("instrument")))
    return error_reply(409, "the two models are in different frames (" + models[0].value("frame", std::string("instrument")) +
                                ", " + models[1].value("frame", std::string("instrument")) + ")");
  json out = compare_json(models[0], models[1]);
  for (int i = 0; i < 2; ++i) {
    const CampaignRow& row = rows[i];
    out[names[i]] = {{"campaign_id", row.id},
                     {"name", row.name},
                     {"serial", row.imu_serial ? json(*row.imu_serial) : json(nullptr)},
                     {"date", iso8601_utc(row.ended_ms.value_or(row.created_ms))},
                     {"frame", models[i].value("frame", std::string("instrument"))}};
  }
  return json_reply(200, out);
}

HttpReply Api::campaign_detail(std::int64_t id) {
  const auto row = db_.campaign(id);
  if (!row) return error_reply(404, "no campaign " + std::to_string(id));
  return json_reply(200, detail_json(*row));
}

json Api::detail_json(const CampaignRow& row) {
  const std::int64_t id = row.id;
  json out = summary(row);
  out["verdict"] = run_verdict(row, limits_.current());
  json spec = parse_or_null(row.spec_json);
  out["spec"] = spec;
  json segments = json::array();
  const CampaignCheck check = check_campaign_text(row.spec_json, config_);
  for (std::size_t i = 0; i < check.segments.size(); ++i) {
    const auto& s = check.segments[i];
    const bool redoable = !check.spec || !check.spec->chamber.ramps_within(s.t0_s, s.t1_s);
    segments.push_back({{"index", i}, {"name", s.name}, {"kind", s.kind}, {"t0_s", s.t0_s}, {"t1_s", s.t1_s},
                        {"redoable", redoable}});
  }
  out["segments"] = segments;
  out["checkpoint"] = row.checkpoint_segment
                          ? json{{"segment", *row.checkpoint_segment}, {"t_s", row.checkpoint_s.value_or(0.0)}}
                          : json(nullptr);
  out["frames"] = row.frames;
  out["lost_frames"] = row.lost_frames;
  out["bad_frames"] = row.bad_frames;
  json transitions = json::array();
  for (const auto& t : db_.transitions(id))
    transitions.push_back({{"t", iso8601_utc(t.t_ms)},
                           {"from", t.from ? json(to_string(*t.from)) : json(nullptr)},
                           {"to", to_string(t.to)},
                           {"reason", t.reason}});
  out["transitions"] = transitions;
  // Started with reference equipment past its due date: who overrode which instrument, and why.
  out["override_overdue"] = overdue_override_json(id);
  json events = json::array();
  for (const auto& e : db_.events(id))
    events.push_back({{"t", iso8601_utc(e.t_ms)},
                      {"kind", e.kind},
                      {"segment", e.segment ? json(*e.segment) : json(nullptr)},
                      {"program_time_s", e.program_time_s ? json(*e.program_time_s) : json(nullptr)},
                      {"reason", e.reason}});
  out["events"] = events;
  json alarms = json::array();
  for (const auto& a : db_.alarms(id, true)) alarms.push_back(alarm_json(a));
  out["alarms"] = alarms;
  // What the run asks the operator now (a power cycle), or null.
  out["prompt"] = sequencer_.prompt_of(id);
  json estimators = sequencer_.active_id() == id ? sequencer_.active_estimators() : parse_or_null(row.estimators_json);
  out["estimators"] = estimators.is_null() ? json::object() : estimators;
  const json results = parse_or_null(row.results_json);
  out["results"] = results.is_null() ? json::object() : results;
  out["run_db"] = row.run_db.empty() ? json(nullptr) : json(row.run_db);
  // The serial the run file records (the IMU's own report; the simulator's for simulated runs).
  json serial = nullptr;
  // A run that is starting names its file a moment before the recorder creates it.
  if (!row.run_db.empty() && std::filesystem::exists(run_path(row))) {
    std::lock_guard lock(serial_mutex_);
    auto it = serial_cache_.find(id);
    if (it == serial_cache_.end()) {
      try {
        it = serial_cache_.emplace(id, imu_serial_of_run(run_path(row))).first;
      } catch (const std::exception& e) {
        spdlog::warn("campaign {}: cannot read the IMU serial from {}: {}", id, row.run_db, e.what());
      }
    }
    if (it != serial_cache_.end()) serial = it->second;
  }
  out["imu_serial"] = serial;
  return out;
}

// The run's test report (test_report.hpp): its figures from the results, the temperatures from
// its recording, the gravity as the certificate states it.
HttpReply Api::campaign_report(std::int64_t id, const std::map<std::string, std::string>& query) {
  const auto row = db_.campaign(id);
  if (!row) return error_reply(404, "no campaign " + std::to_string(id));
  TemperatureSummary temperatures;
  if (!row->run_db.empty() && std::filesystem::exists(run_path(*row))) {
    try {
      temperatures = summarize_temperatures(run_temperatures(run_path(*row)));
    } catch (const std::exception& e) {
      spdlog::warn("campaign {}: the report goes without temperatures: {}", id, e.what());
    }
  }
  json report = test_report_json(detail_json(*row), certificate_bench_json(config_, row->ended_ms.value_or(0)), temperatures);
  // ?signed=1: the report in the lab's signed envelope (imucal-signed/1, kind test-report), the
  // file `imucal verify` checks; signed as it reads now (a report is not frozen as a certificate is).
  const auto& key = certificates_.signing_key();
  if (const auto it = query.find("signed"); it != query.end() && it->second != "0") {
    if (!key)
      return error_reply(409, "the lab has no signing key (certificates.signing_key_file in the configuration): nothing is signed");
    return json_reply(200, signing::sign_document(report, signing::kTestReport, *key));
  }
  report["signed_by"] = key ? json(signing::fingerprint(key->public_key)) : json(nullptr);
  return json_reply(200, report);
}

namespace {

json text_or_null(const std::optional<std::string>& text) { return text ? json(*text) : json(nullptr); }

json page_json(const IssuedPageRow& p) {
  return {{"number", p.number}, {"sha256", p.sha256}, {"stored", iso8601_utc(p.stored_ms)}, {"stored_by", p.stored_by}};
}

}  // namespace

json Api::issued_json(const IssuedCertificateRow& c) {
  const json content = parse_or_null(c.content_json);
  json out = {{"number", c.number},
              {"sequence", c.sequence},
              {"campaign_id", c.campaign_id},
              {"issued", iso8601_utc(c.issued_ms)},
              {"reason", c.reason},
              {"supersedes", text_or_null(c.supersedes)},
              {"superseded_by", text_or_null(c.superseded_by)},
              {"content_sha256", c.content_sha256},
              {"content", content},
              {"signed", parse_or_null(c.signed_json)}};
  // The bench's keys at the top too, as before certificates were frozen.
  if (content.is_object() && content.value("bench", json()).is_object()) out.update(content.at("bench"));
  json history = json::array();
  for (const auto& h : registry_.issued_history(c.campaign_id))
    history.push_back({{"number", h.number},
                       {"issued", iso8601_utc(h.issued_ms)},
                       {"reason", h.reason},
                       {"superseded_by", text_or_null(h.superseded_by)}});
  out["history"] = history;
  const auto page = registry_.issued_page(c.number, false);
  out["page"] = page ? page_json(*page) : json(nullptr);
  // Said on reading, never written into the issued content: the content stays as issued.
  out["gravity_corrected"] = gravity_correction(content, config_);
  return out;
}

HttpReply Api::campaign_certificate(std::int64_t id) {
  const auto row = db_.campaign(id);
  if (!row) return error_reply(404, "no campaign " + std::to_string(id));
  if (const auto current = registry_.current_issued(id)) return json_reply(200, issued_json(*current));
  if (const std::string why = no_certificate_because(*row); !why.empty()) return error_reply(409, why);
  try {
    // A run that ended before certificates were issued at the end, or whose issue failed then.
    if (const auto issued = certificates_.issue(id, "issued at its first request")) return json_reply(200, issued_json(*issued));
  } catch (const std::exception& e) {
    spdlog::error("campaign {}: no certificate: {}", id, e.what());
    return error_reply(503, std::string("no certificate number can be issued: ") + e.what());
  }
  return error_reply(409, "campaign " + std::to_string(id) + " has no certificate");
}

// The page as printed: the browser renders it from the issued content (certificate.mjs) and sends
// the self-contained HTML once; it must state the certificate's number and content hash, the two
// things that tie it to the signed record.
HttpReply Api::store_certificate_page(const std::string& number, const ApiRequest& request, const Principal& who) {
  const auto c = registry_.issued(number);
  if (!c) return error_reply(404, "no certificate numbered '" + number + "' was issued here");
  json body;
  if (auto bad = parse_body(request, body)) return *bad;
  if (!body.is_object() || !body.contains("html") || !body.at("html").is_string())
    return error_reply(400, "the body must be {\"html\": \"<the page as printed>\"}");
  std::string html = body.at("html").get<std::string>();
  if (html.find(c->number) == std::string::npos || html.find(c->content_sha256) == std::string::npos)
    return error_reply(400, "body.html is not certificate " + c->number +
                                "'s page: it must state the certificate's number and its content SHA-256");
  IssuedPageRow page{number, std::move(html), "", now_unix_ms(), who.user};
  page.sha256 = signing::sha256_hex(page.html);
  if (!registry_.insert_issued_page(page)) {
    const IssuedPageRow stored = expect_value(registry_.issued_page(number, false), "the page stored before");
    return error_reply(409, "certificate " + number + "'s page was stored on " + iso8601_utc(stored.stored_ms) + " by " +
                                stored.stored_by + " (SHA-256 " + stored.sha256 + "); a stored page never changes");
  }
  audit_.append(who.user, "certificate.page_stored", number, {{"sha256", page.sha256}, {"bytes", page.html.size()}});
  return json_reply(201, page_json(page));
}

HttpReply Api::certificate_page(const std::string& number) {
  const auto page = registry_.issued_page(number, true);
  if (!page)
    return error_reply(404, registry_.issued(number) ? "certificate " + number + "'s page has not been stored (an operator's first opening of it stores it)"
                                               : "no certificate numbered '" + number + "' was issued here");
  HttpReply r;
  r.body = page->html;
  r.content_type = "text/html; charset=utf-8";
  r.headers.emplace_back("Cache-Control", "no-store");
  r.headers.emplace_back("Content-Disposition", "attachment; filename=\"certificate-" + file_name_part(number) + ".html\"");
  return r;
}

HttpReply Api::certificate_by_number(const std::string& number) {
  const auto c = registry_.issued(number);
  if (!c) return error_reply(404, "no certificate numbered '" + number + "' was issued here");
  return json_reply(200, issued_json(*c));
}

// The campaign's model against its simulation's truth, the truth turned into the model's frame
// (estimators/truth_comparison.hpp, the comparison `imucal compare` prints).
HttpReply Api::campaign_truth(std::int64_t id) {
  const auto row = db_.campaign(id);
  if (!row) return error_reply(404, "no campaign " + std::to_string(id));
  if (!row->model_json)
    return error_reply(404, "campaign " + std::to_string(id) + " has no model (state " +
                                std::string(to_string(row->state)) + ")");
  const json spec = json::parse(row->spec_json, nullptr, false);
  if (!spec.is_object() || !spec.contains("truth") || !spec.at("truth").is_object())
    return error_reply(404, "campaign " + std::to_string(id) + " has no simulated truth");
  return json_reply(200, truth_comparison_json(*row->model_json, spec.at("truth").dump()));
}

HttpReply Api::campaign_model(std::int64_t id, const std::map<std::string, std::string>& query) {
  const auto row = db_.campaign(id);
  if (!row) return error_reply(404, "no campaign " + std::to_string(id));
  if (!row->model_json)
    return error_reply(404, "campaign " + std::to_string(id) + " has no model (state " +
                                std::string(to_string(row->state)) + ")");
  const auto asked = [&](const char* key) {
    const auto it = query.find(key);
    return it == query.end() ? std::nullopt : std::optional<std::string>(it->second);
  };
  const ModelView view = stored_model_view(*row->model_json, row->results_json, asked("stage"), asked("frame"));
  if (view.status == 404) return error_reply(404, "campaign " + std::to_string(id) + " has " + view.text);
  if (view.status != 200) return error_reply(view.status, view.text);
  const std::string& text = view.text;
  HttpReply r;
  r.body = text;
  r.content_type = "application/json";
  r.headers.emplace_back("Cache-Control", "no-store");
  // Each download its own name: the instrument- and body-frame models (and each stage's) must
  // not overwrite each other in a downloads folder.
  std::string file = "campaign-" + std::to_string(id);
  if (const auto stage = query.find("stage"); stage != query.end()) file += "-" + stage->second;
  // Named by the frame of what is sent (a stage-3 model is in the body frame already).
  const json sent = json::parse(text, nullptr, false);
  file += "-model-" + (sent.is_object() ? sent.value("frame", std::string("instrument")) : std::string("instrument"));
  r.headers.emplace_back("Content-Disposition", "inline; filename=\"" + file + ".json\"");
  return r;
}

HttpReply Api::campaign_progress(std::int64_t id) {
  if (!db_.campaign(id)) return error_reply(404, "no campaign " + std::to_string(id));
  json out = json::object();
  for (const auto& p : db_.progress(id)) {
    json entry = parse_or_null(p.json);
    if (!entry.is_object()) continue;
    entry["program_time_s"] = p.program_time_s;
    entry["t"] = iso8601_utc(p.t_ms);
    out[p.estimator].push_back(std::move(entry));
  }
  return json_reply(200, out);
}

namespace {

// Instruments past their due date, as the 409 of a start, the override's audit entry and its
// record with the run name them. `with_line`: each with its line for a person (due_line, which
// counts the days from today: the 409's, for the UI's dialog; not for what is kept).
json overdue_json(const std::vector<InstrumentDue>& overdue, bool with_line = false) {
  json out = json::array();
  for (const InstrumentDue& d : overdue) {
    json i = {{"instrument", d.instrument}, {"identity", d.identity}, {"serial", d.serial},
              {"certificate", d.certificate}, {"calibration_due", d.calibration_due}};
    if (with_line) i["text"] = due_line(d);
    out.push_back(std::move(i));
  }
  return out;
}

bool blank(const std::string& text) { return text.find_first_not_of(" \t\r\n") == std::string::npos; }

}  // namespace

std::vector<InstrumentDue> Api::overdue_for_start(std::int64_t id) {
  std::vector<InstrumentDue> overdue;
  const auto row = db_.campaign(id);
  if (!row || row->state != RunState::Created) return overdue;
  for (InstrumentDue& d : equipment_due(config_.reference_equipment, utc_day(now_unix_ms())))
    if (d.overdue) overdue.push_back(std::move(d));
  return overdue;
}

json Api::overdue_override_json(std::int64_t id) {
  std::optional<OverdueOverrideRow> o;
  try {
    o = registry_.overdue_override(id);
  } catch (const std::exception& e) {
    // The registry's server away: the campaign's page is still shown (its run goes on), saying so.
    if (!is_database_failure(e)) throw;
    return {{"unavailable", e.what()}};
  }
  if (!o) return nullptr;
  return {{"by", o->by}, {"at", iso8601_utc(o->t_ms)}, {"reason", o->reason},
          {"instruments", parse_or_null(o->instruments_json)}, {"text", o->text}};
}

// A start while reference equipment is past its due date (judged today, UTC, by the one rule,
// equipment_due) is refused with 409 naming each instrument, unless the request overrides it with
// a reason. Only a campaign that start would queue is judged: another state gets the sequencer's
// own answer. The override is recorded with the run before the sequencer is asked (and removed
// when it refuses), so that no run can end, and be certified, without it.
Api::CommandAnswer Api::command_campaign(std::int64_t id, Command command, const CommandRequest& request) {
  const std::optional<std::string>& override_overdue = request.override_overdue;
  std::string problem;
  if (override_overdue && command != Command::Start)
    problem = request.override_name + " applies to start only (a run already started is not judged again)";
  else if (override_overdue && blank(*override_overdue))
    problem = request.override_name + " must say why the campaign starts with reference equipment past its due date";
  if (!problem.empty()) return {400, problem, {{"problems", json::array({problem})}}, {}};

  std::unique_lock start_lock(start_mutex_, std::defer_lock);
  std::vector<InstrumentDue> overdue;
  if (command == Command::Start) {
    start_lock.lock();
    overdue = overdue_for_start(id);
  }
  if (!overdue.empty() && !override_overdue) {
    const auto row = db_.campaign(id);
    return {409,
            "campaign " + std::to_string(id) + " not started: reference equipment is past its due date: " +
                overdue_text(overdue) + ". Calibrate it (and update reference_equipment in the configuration), or " +
                request.how_to_override,
            {{"state", row ? json(to_string(row->state)) : json(nullptr)}, {"overdue", overdue_json(overdue, true)}},
            {}};
  }
  const std::string override_reason = override_overdue.value_or("").substr(0, 500);
  // The overridden instruments in words and as kept, composed once for the run record, the log and
  // the audit trail.
  const std::string overdue_words = overdue_text(overdue);
  const json overdue_kept = overdue_json(overdue);
  // The run's own record says so too: the transition's reason names what was overridden and why.
  std::string stored_reason = request.reason;
  if (!overdue.empty()) {
    stored_reason += (request.reason.empty() ? "" : "; ") + std::string("overdue reference equipment overridden (") +
                     overdue_words + "): " + override_reason;
    registry_.insert_overdue_override({id, now_unix_ms(), request.user, override_reason, overdue_kept.dump(), overdue_words});
  }
  const auto outcome = sequencer_.command(id, command, request.user, stored_reason);
  if (outcome.http_status != 200) {
    if (!overdue.empty()) registry_.remove_overdue_override(id);
    json extra = json::object();
    if (outcome.state) extra["state"] = to_string(*outcome.state);
    return {outcome.http_status, outcome.error, extra, {}};
  }
  const std::string name(to_string(command));
  if (!overdue.empty()) {
    spdlog::warn("campaign {}: started by {} with overdue reference equipment ({}): {}", id, request.user, overdue_words,
                 override_reason);
    audit_.append(request.user, "campaign.override_overdue", "campaign " + std::to_string(id),
          {{"command", name}, {"instruments", overdue_kept}, {"reason", override_reason}});
  }
  // A command that succeeded has moved the campaign to its new state.
  const std::string state(to_string(expect_value(outcome.state, "the state after a command that succeeded")));
  audit_.append(request.user, "campaign.command", "campaign " + std::to_string(id),
        {{"command", name}, {"reason", request.reason}, {"state", state}});
  return {200, {}, json::object(), state};
}

HttpReply Api::campaign_command(std::int64_t id, const std::string& command, const ApiRequest& request,
                                const Principal& who) {
  json body;
  if (auto bad = parse_body(request, body)) return *bad;
  std::vector<std::string> problems;
  CommandRequest ask{who.user, {}, {}, "body.override_overdue",
                     "start anyway as an operator with a reason: POST /api/campaigns/" + std::to_string(id) +
                         "/start with {\"override_overdue\": \"why\"} (kept in the audit trail and stated on the "
                         "run's certificate)"};
  {
    ObjectReader r(body, "body", problems);
    if (auto v = r.string("reason")) ask.reason = v->substr(0, 500);
    ask.override_overdue = r.string("override_overdue");
  }
  if (!problems.empty()) return error_reply(400, problems.front(), {{"problems", problems}});
  // The route matches only a command's name ({command}).
  const CommandAnswer answer =
      command_campaign(id, expect_value(parse_command(command), "the command the route matched"), ask);
  if (answer.status != 200) return error_reply(answer.status, answer.error, answer.extra);
  return json_reply(200, {{"id", id}, {"state", answer.state}});
}

// The operator's answer to what the run asks (a power cycle of the IMU): {"answer": "done"}.
HttpReply Api::campaign_prompt(std::int64_t id, const ApiRequest& request, const Principal& who) {
  json body;
  if (auto bad = parse_body(request, body)) return *bad;
  std::vector<std::string> problems;
  {
    ObjectReader r(body, "body", problems);
    if (auto v = r.string("answer", true); v && *v != "done")
      problems.push_back("body.answer must be \"done\" (the IMU was switched off and on again), not \"" + *v + "\"");
  }
  if (!problems.empty()) return error_reply(400, problems.front(), {{"problems", problems}});
  if (!db_.campaign(id)) return error_reply(404, "no campaign " + std::to_string(id));
  const auto outcome = sequencer_.answer_prompt(id, who.user);
  if (outcome.http_status != 200) return error_reply(outcome.http_status, outcome.error);
  audit_.append(who.user, "campaign.prompt_answered", "campaign " + std::to_string(id), {{"answer", "done"}});
  return json_reply(200, {{"id", id}, {"answered", "done"}});
}

std::string Api::run_path(const CampaignRow& row) const {
  return (std::filesystem::path(config_.data_dir) / row.run_db).string();
}

std::optional<HttpReply> Api::no_recording(const CampaignRow& row, const std::string& prefix) const {
  if (row.run_db.empty())
    return error_reply(404, prefix + "campaign " + std::to_string(row.id) + " has no recording (it was never started)");
  // Named when the run starts, written from its first frame: a run that failed before it (or
  // one starting this instant) has none yet.
  std::error_code ec;
  if (!std::filesystem::exists(run_path(row), ec))
    return error_reply(404, prefix + "campaign " + std::to_string(row.id) + " has no recording yet (state " +
                                std::string(to_string(row.state)) + ")");
  return std::nullopt;
}

namespace {
// Where a run's recording bundle is written (DATA_DIR/exports/) and what it is made from.
struct RecordingExport {
  std::string name;  // the bundle's folder and the tar file's name without ".tar"
  std::filesystem::path tar, run;
  // Made, and not older than the run file (an interrupted run resumed since makes it stale).
  bool fresh() const {
    std::error_code ec;
    const bool made = std::filesystem::exists(tar, ec);
    return made && std::filesystem::last_write_time(tar, ec) >= std::filesystem::last_write_time(run, ec) && !ec;
  }
  HttpReply reply() const {
    HttpReply r;
    r.content_type = "application/x-tar";
    r.file = tar.string();  // the server answers HEAD with the file's length and no body
    r.headers.emplace_back("Cache-Control", "no-store");
    r.headers.emplace_back("Content-Disposition", "attachment; filename=\"" + name + ".tar\"");
    return r;
  }
};
}  // namespace

HttpReply Api::campaign_recording(std::int64_t id) {
  const auto row = db_.campaign(id);
  if (!row) return error_reply(404, "no campaign " + std::to_string(id));
  // Queued or active first: a queued run has no run file yet, but it will (409, not 404).
  if (is_active(row->state) || row->state == RunState::Queued)
    return error_reply(409, "campaign " + std::to_string(id) + " is " + std::string(to_string(row->state)) +
                                ": its recording can be downloaded when the run has ended",
                       {{"state", to_string(row->state)}});
  if (auto none = no_recording(*row)) return *none;
  RecordingExport bundle;
  bundle.name = "campaign-" + std::to_string(id) + "-recording";
  bundle.tar = std::filesystem::path(config_.data_dir) / "exports" / (bundle.name + ".tar");
  bundle.run = run_path(*row);
  AnalysisJobs::Key key;
  key.campaign = id;
  key.analysis = "recording";
  key.state = to_string(row->state);
  // While a job writes the bundle, its progress is the answer: the file appears (renamed into
  // place) before the job has pruned the folder and finished.
  if (const auto pending = jobs_->find(key); pending && !pending->ready) return job_reply(*pending);
  // The bundle on the disk is the answer kept, not the job's (a finished job's is dropped): a
  // failure is tried again at the next request, and a bundle removed since
  // (http.exports_max_bytes) is written again.
  jobs_->forget(key);
  if (bundle.fresh()) return bundle.reply();
  // Written as a job (minutes for a long run), never on the HTTP thread: 202 with its progress.
  auto compute = [this, id, bundle](const AnalysisJobs::Progress& progress) -> std::pair<int, json> {
    std::lock_guard lock(export_mutex_);  // one writer of DATA_DIR/exports/ at a time
    if (!bundle.fresh()) {
      std::filesystem::create_directories(bundle.tar.parent_path());
      spdlog::info("campaign {}: exporting the recording bundle to {}", id, bundle.tar.string());
      write_recording_tar(bundle.run.string(), bundle.tar.string(), bundle.name, progress);
      if (const int removed = prune_exports(bundle.tar.parent_path().string(), bundle.tar.string(),
                                            config_.http.exports_max_bytes))
        spdlog::info("exports: {} older recording bundle(s) removed to stay within http.exports_max_bytes", removed);
    }
    return {200, {{"campaign", id}, {"bytes", std::filesystem::file_size(bundle.tar)}}};
  };
  const AnalysisJobs::Answer answer = jobs_->request(key, std::move(compute));
  if (!answer.ready) return job_reply(answer);
  jobs_->forget(key);
  return answer.status == 200 ? bundle.reply() : job_reply(answer);
}

// A bundle of the lab's shared archive (registry.archive_dir): any stand's run that ended, served
// by this stand, so that a unit's history can fetch a recording whose stand is away.
HttpReply Api::archived_recording_reply(const std::string& stand, const std::string& campaign) {
  const std::string archive = archive_dir_path(config_);
  if (archive.empty()) return error_reply(404, "this stand has no shared archive of recordings (registry.archive_dir)");
  const auto id = parse_id(campaign);
  if (!id) return error_reply(400, "the campaign must be a campaign id, not '" + campaign + "'");
  RecordingExport bundle;
  bundle.name = "campaign-" + std::to_string(*id) + "-recording";
  bundle.tar = archived_recording(archive, stand, *id);
  std::error_code ec;
  if (!std::filesystem::is_regular_file(bundle.tar, ec))
    return error_reply(404, "the lab's archive holds no recording of campaign " + std::to_string(*id) + " of stand '" +
                                stand + "'");
  return bundle.reply();
}

HttpReply Api::list_alarms(const std::map<std::string, std::string>& query) {
  std::optional<std::int64_t> campaign;
  if (const auto it = query.find("campaign"); it != query.end()) {
    campaign = parse_id(it->second);
    if (!campaign) return error_reply(400, "campaign must be a campaign id (/api/alarms?campaign=ID), not '" + it->second + "'");
    if (!db_.campaign(*campaign)) return error_reply(404, "no campaign " + std::to_string(*campaign));
  }
  bool all = false;
  if (const auto it = query.find("all"); it != query.end()) {
    if (it->second != "0" && it->second != "1") return error_reply(400, "all must be 0 or 1, not '" + it->second + "'");
    all = it->second == "1";
  }
  auto rows = db_.alarms(campaign, all);
  json list = json::array();
  for (auto it = rows.rbegin(); it != rows.rend(); ++it) list.push_back(alarm_json(*it));
  return json_reply(200, {{"alarms", list}});
}

namespace {

// One key of GET /api/audit's query into `q`; the 400's text when it is wrong, else empty.
std::string read_audit_key(const std::string& key, const std::string& value, DaemonDb::AuditQuery& q) {
  if (key == "from" || key == "to") {
    const std::int64_t day = date_day_number(value).value_or(std::numeric_limits<std::int64_t>::min());
    if (day == std::numeric_limits<std::int64_t>::min()) return key + " must be a date YYYY-MM-DD (UTC), not '" + value + "'";
    if (key == "from") q.from_ms = day * 86'400'000;
    else q.to_ms = (day + 1) * 86'400'000 - 1;  // the whole day
  } else if (key == "actor") {
    q.actor = value;
  } else if (key == "action") {
    q.action_prefix = value;
  } else if (key == "subject") {
    q.subject = value;
  } else if (key == "limit") {
    const std::int64_t limit = parse_id(value).value_or(0);
    if (limit < 1 || limit > 100000) return "limit must be a number from 1 to 100000, not '" + value + "'";
    q.limit = limit;
  } else if (key != "format") {
    return "unknown query key '" + key + "' (from, to, actor, action, subject, limit, format)";
  }
  return {};
}

HttpReply audit_csv(const std::vector<AuditEntry>& entries) {
  HttpReply r;
  r.body = "seq,time_utc,actor,action,subject,details,sha256\r\n";
  for (const auto& e : entries)
    r.body += std::to_string(e.seq) + "," + iso8601_utc(e.t_ms) + "," + csv_field(e.actor) + "," + csv_field(e.action) +
              "," + csv_field(e.subject) + "," + csv_field(e.details_json) + "," + e.sha256 + "\r\n";
  r.content_type = "text/csv; charset=utf-8";
  r.headers.emplace_back("Cache-Control", "no-store");
  r.headers.emplace_back("Content-Disposition", "attachment; filename=\"imucal-audit.csv\"");
  return r;
}

}  // namespace

// GET /api/audit: the trail, newest first, filtered; ?format=csv for a spreadsheet.
HttpReply Api::list_audit(const std::map<std::string, std::string>& query) {
  DaemonDb::AuditQuery q;
  for (const auto& [key, value] : query)
    if (const std::string bad = read_audit_key(key, value, q); !bad.empty()) return error_reply(400, bad);
  const auto format_it = query.find("format");
  const std::string format = format_it == query.end() ? std::string("json") : format_it->second;
  if (format != "json" && format != "csv") return error_reply(400, "format must be json or csv, not '" + format + "'");
  const auto entries = registry_.audit_entries(q);
  if (format == "csv") return audit_csv(entries);
  json list = json::array();
  for (const auto& e : entries)
    list.push_back({{"seq", e.seq},
                    {"t", iso8601_utc(e.t_ms)},
                    {"actor", e.actor},
                    {"action", e.action},
                    {"subject", e.subject},
                    {"details", parse_or_null(e.details_json)},
                    {"sha256", e.sha256}});
  const AuditCheck check = check_audit_chain(registry_.audit_chain());
  return json_reply(200, {{"entries", list}, {"intact", check.ok()}, {"check", check.message}});
}

HttpReply Api::acknowledge_alarm(const std::string& id_text, const Principal& who) {
  const auto id = parse_id(id_text);
  if (!id) return error_reply(404, "no alarm '" + id_text + "': an alarm id is a number (GET /api/alarms lists them)");
  const auto ack = db_.acknowledge_alarm(*id, who.user);
  // Every outcome but NoSuchAlarm comes with the row.
  if (ack.first == DaemonDb::Ack::NoSuchAlarm || !ack.second) return error_reply(404, "no alarm " + std::to_string(*id));
  const AlarmRow& row = *ack.second;
  if (ack.first == DaemonDb::Ack::AlreadyAcknowledged)
    return error_reply(409,
                       "alarm " + std::to_string(*id) + " was already acknowledged by " + row.acknowledged_by.value_or("?") +
                           " at " + iso8601_utc(row.acknowledged_ms.value_or(0)),
                       {{"alarm", alarm_json(row)}});
  spdlog::info("campaign {}: alarm {} ({}: {}) acknowledged by {}", row.campaign_id, row.id, row.severity,
               row.message, who.user);
  broadcast(alarm_message("acknowledged", row));
  audit_.append(who.user, "alarm.acknowledged", "alarm " + std::to_string(row.id),
        {{"campaign", row.campaign_id}, {"severity", row.severity}, {"message", row.message}});
  return json_reply(200, alarm_json(row));
}

HttpReply Api::campaign_events_csv(std::int64_t id) {
  if (!db_.campaign(id)) return error_reply(404, "no campaign " + std::to_string(id));
  HttpReply r;
  r.body = run_log_csv(db_.transitions(id), db_.events(id), db_.alarms(id, true, std::numeric_limits<std::int64_t>::max()));
  r.content_type = "text/csv; charset=utf-8";
  r.headers.emplace_back("Cache-Control", "no-store");
  r.headers.emplace_back("Content-Disposition", "attachment; filename=\"campaign-" + std::to_string(id) + "-events.csv\"");
  return r;
}

void Api::broadcast(const json& message) {
  std::lock_guard lock(listener_mutex_);
  if (event_listener_) event_listener_(message);
}

HttpReply Api::campaign_series(std::int64_t id, const std::map<std::string, std::string>& query) {
  const auto row = db_.campaign(id);
  if (!row) return error_reply(404, "no campaign " + std::to_string(id));
  if (auto none = no_recording(*row)) return *none;
  SeriesRange range;
  // A query value that is not a number is named, not read as 0.
  for (const auto& [key, target] : {std::pair<const char*, double*>{"from_s", &range.from_s}, {"to_s", &range.to_s}}) {
    const auto it = query.find(key);
    if (it == query.end()) continue;
    const auto seconds = parse_number_text(it->second);
    if (!seconds) return error_reply(400, std::string(key) + " must be a number of seconds, not '" + it->second + "'");
    *target = *seconds;
  }
  // An empty range asked for is the client's mistake (to_s <= from_s otherwise means "to the end").
  if (query.contains("to_s") && range.to_s <= range.from_s)
    return error_reply(400, "to_s (" + query.at("to_s") + ") must be after from_s (" + number_text(range.from_s) + ")");
  if (const auto it = query.find("points"); it != query.end()) {
    const auto v = parse_id(it->second);
    if (!v || *v < 1 || *v > kMaxSeriesColumns)
      return error_reply(400, "points must be a number from 1 to " + std::to_string(kMaxSeriesColumns));
    range.columns = static_cast<int>(*v);
  }
  try {
    return json_reply(200, run_series_of(run_path(*row), range));
  } catch (const std::invalid_argument& e) {
    return error_reply(400, e.what());
  }
}

void Api::set_event_listener(std::function<void(const json&)> listener) {
  std::lock_guard lock(listener_mutex_);
  event_listener_ = std::move(listener);
}

HttpReply Api::campaign_analysis(std::int64_t id, const std::string& what) {
  const auto row = db_.campaign(id);
  if (!row) return error_reply(404, "no campaign " + std::to_string(id));
  const std::string label = what == "allan" ? "Allan deviation" : what == "thermal" ? "thermal plots" : "Schuler test";
  if (is_active(row->state) || row->state == RunState::Queued)
    return error_reply(409, "campaign " + std::to_string(id) + " is " + std::string(to_string(row->state)) + ": the " +
                                label + " is computed when the run has ended",
                       {{"state", to_string(row->state)}});
  if (auto none = no_recording(*row, "not available for this run: ")) return *none;
  // A job off the I/O thread (AnalysisJobs): the row is copied, the request answered at once.
  auto compute = [this, id, what, row = *row](const AnalysisJobs::Progress& progress) -> std::pair<int, json> {
    const std::string path = run_path(row);
    std::optional<ImuModel> model;
    if (row.model_json) model = imu_model_from_json_text(*row.model_json, "campaign " + std::to_string(id) + "'s model");
    int status = 200;
    json body;
    try {
      if (what == "allan") {
        body = allan_from_run(path, progress);
      } else if (what == "thermal") {
        // Stage 2 starts from stage 1's model (instrument frame): the campaign's, or the one its
        // direct stage kept when later stages (stage 3: body frame) followed it.
        std::optional<ImuModel> stage1 = model && model->frame == "instrument" ? model : std::nullopt;
        if (row.results_json) {
          const json results = json::parse(*row.results_json, nullptr, false);
          if (results.is_object() && results.contains("direct") && results.at("direct").contains("model"))
            stage1 = imu_model_from_json_text(results.at("direct").at("model").dump(), "the direct stage's model");
        }
        body = thermal_from_run(path, stage1.value_or(ImuModel{}), progress);
        body["input_model"] = stage1 ? "the campaign's stage-1 model" : "ideal (the campaign has no stage-1 model)";
      } else {
        std::vector<Variant> variants;
        variants.push_back({"uncalibrated", "no compensation (the nominal sensor)", ImuModel{}});
        // Each calibration stage's model when the campaign kept several (a `full` campaign: direct,
        // lever-arm, stage3), else its one model.
        const std::vector<Variant> stages = stage_model_variants(row.results_json);
        if (stages.size() > 1) {
          variants.insert(variants.end(), stages.begin(), stages.end());
        } else if (model) {
          variants.push_back({"campaign " + std::to_string(id), "this campaign's model", *model});
        }
        const CampaignCheck check = check_campaign_text(row.spec_json, config_);
        if (check.spec && check.spec->navigation_model)
          variants.push_back({"navigation_model", "the campaign's navigation_model", *check.spec->navigation_model});
        if (const auto truth = truth_of_run(path)) variants.push_back({"truth", "the simulation's truth (the best any calibration can do)", *truth});
        body = evaluation_from_run(path, variants, progress);
      }
    } catch (const NotAvailable& e) {
      // What this run cannot give is an answer, not an error (docs/api.md): the results page asks
      // every run, and a 404 would be logged as an error in every browser's console.
      body = {{"available", false}, {"reason", e.what()}};
    }
    return {status, body};
  };
  AnalysisJobs::Key key;
  key.campaign = id;
  key.analysis = what;
  key.state = to_string(row->state);
  return job_reply(jobs_->request(key, std::move(compute)));
}

HttpReply Api::job_reply(const AnalysisJobs::Answer& a) {
  if (a.ready) {
    HttpReply r = json_reply(a.status, json::object());
    r.body = a.body;
    if (a.status == 429) r.headers.emplace_back("Retry-After", "5");
    return r;
  }
  // 202: computing (or queued); ask again. The live WebSocket carries the same progress.
  HttpReply r = json_reply(202, a.pending);
  r.headers.emplace_back("Retry-After", "1");
  return r;
}

// What the campaign's program will deliver, before it runs (`imucal plan`, docs/programs.md): the
// body is a campaign as for validation, with an optional `plan` object: `rate_hz` (default 20: a
// few seconds for the `navigation` program), `arw_deg_rth` and `vrw_mps_rth` (the unit's noise;
// default the campaign's truth's). A job like the analyses: 202 with progress until ready; the
// same body again finds the answer kept.
HttpReply Api::plan_campaign(const ApiRequest& request) {
  json body;
  if (auto bad = parse_body(request, body)) return *bad;
  json options = json::object();
  if (body.is_object() && body.contains("plan")) {
    options = body.at("plan");
    body.erase("plan");
    if (!options.is_object()) return error_reply(400, "plan must be an object");
  }
  const CampaignCheck check = check_campaign(body, config_);
  if (check.malformed) return malformed_campaign(check);
  if (!check.spec) return error_reply(422, "campaign is invalid", {{"problems", check.problems}});
  ImuModel unit = check.spec->truth;
  double rate_hz = 20.0;
  std::vector<std::string> problems;
  {
    ObjectReader r(options, "plan", problems);
    if (auto v = r.number_in("rate_hz", 1.0, 1000.0)) rate_hz = *v;
    if (auto v = r.number_in("arw_deg_rth", 0.0)) unit.gyro.noise.arw_rad_rts = *v * units::kDegRthToRadRts;
    if (auto v = r.number_in("vrw_mps_rth", 0.0)) unit.accel.noise.vrw_mps_rts = *v * units::kMpsRthToMpsRts;
  }
  if (!problems.empty()) return error_reply(422, problems.front(), {{"problems", problems}});
  const motion::Program program = compile_campaign_program(*check.spec, config_);
  // The bench as its runs record it: the table's certificate (stage 1's budget and the table it
  // needs) and the site (a configured g is a measured one).
  auto compute = [program, unit, rate_hz, table = config_.table_certificate,
                  site = config_.site](const AnalysisJobs::Progress& progress) -> std::pair<int, json> {
    plan::Options o;
    o.rate_hz = rate_hz;
    o.progress = progress;
    o.table = table;
    o.site = site;
    try {
      return {200, plan::predict(program, unit, o).to_json()};
    } catch (const std::invalid_argument& e) {
      return {422, {{"error", e.what()}}};
    }
  };
  AnalysisJobs::Key key;
  key.analysis = "plan";
  key.state = json_text(json{{"campaign", check.spec->normalized}, {"plan", {{"rate_hz", rate_hz},
              {"arw", unit.gyro.noise.arw_rad_rts}, {"vrw", unit.accel.noise.vrw_mps_rts}}}});
  return job_reply(jobs_->request(key, std::move(compute)));
}

}  // namespace imucal::daemon
