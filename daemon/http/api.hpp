// The HTTP API of docs/api.md as plain request -> reply functions, with no networking in them:
// routing, authentication and roles, JSON bodies, error replies. The Beast server
// (http_server.cpp) only moves bytes; tests can call handle() directly.
#pragma once

#include <atomic>
#include <chrono>
#include <functional>
#include <memory>
#include <map>
#include <mutex>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include <nlohmann/json.hpp>

#include "daemon/analysis/analysis_jobs.hpp"
#include "daemon/config/config.hpp"
#include "daemon/db/daemon_db.hpp"
#include "daemon/http/auth.hpp"
#include "daemon/http/static_files.hpp"
#include "daemon/production/certificate_issuer.hpp"
#include "daemon/production/limits_file.hpp"
#include "daemon/production/reference_equipment.hpp"
#include "daemon/registry/audit_trail.hpp"
#include "daemon/registry/registry.hpp"
#include "daemon/sequencer/sequencer.hpp"

namespace imucal::daemon {

struct Recalibration;

struct ApiRequest {
  std::string method;  // "GET", "POST", ...
  std::string target;  // path and query as received
  std::string authorization;
  std::string cookie;
  std::string content_type;
  std::string body;
  std::string origin;  // the Origin header (browsers send it on cross-site and on most non-GET requests)
  std::string host;    // the Host header
  std::string client;  // the peer's address (empty in-process): sign-in throttling is per client
};

// Whether an Origin header names the service the Host header names (scheme aside): a browser's
// request from another site carries that site's origin.
bool same_origin(std::string_view origin, std::string_view host);

inline constexpr const char* kSessionCookie = "imucal_session";

class Api {
 public:
  // `registry`: where certificates, their numbers, overrides and the audit trail are kept (the
  // daemon's database or the lab's PostgreSQL server, daemon/registry/registry.hpp). `audit`: how
  // every change is written to the trail; `certificates`: where they are issued (the service owns
  // both: the run's subscribers use them too).
  Api(const DaemonConfig& config, DaemonDb& db, Registry& registry, Sequencer& sequencer, Auth& auth,
      const AuditTrail& audit, CertificateIssuer& certificates);
  struct Route;  // one endpoint: method, path pattern, access, handler (api.cpp)

  // Any /api/ request except the WebSocket.
  HttpReply handle(const ApiRequest& request);
  // Who is asking: bearer token, session cookie, or (WebSocket only) ?token= in the query.
  std::optional<Principal> authenticate(const ApiRequest& request, bool allow_query_token);
  nlohmann::json status();
  // For the live WebSocket: has the session that opened it ended (sign-out, idle timeout)?
  bool session_alive(const std::string& session_id) { return auth_.session_alive(session_id); }
  // From now on every change is refused with 503.
  void set_shutting_down() { shutting_down_ = true; }
  // The acceptance limits in force (read from the registry at each call).
  const LimitsFile& limits() const { return limits_; }
  // Where the analyses' progress is published ({"type": "analysis", ...}, docs/api.md).
  void set_event_listener(std::function<void(const nlohmann::json&)> listener);
  // A command to a campaign as a person gives it, through the API or `imucal campaign run`
  // (campaign_runner.cpp): the one place a start is judged against the reference equipment's due
  // dates (equipment_due), an override of overdue equipment checked, recorded with the run (its
  // certificate states it), audited and logged, and the command audited.
  struct CommandRequest {
    std::string user;                             // who gives it (the audit trail's actor)
    std::string reason;                           // the operator's reason for the command (may be empty)
    std::optional<std::string> override_overdue;  // start only: why overdue equipment does not stop it
    // How the caller names the override to a person, for the refusals: "body.override_overdue"
    // and "POST /api/campaigns/7/start with {...}" for the API, the CLI's option for the CLI.
    std::string override_name;
    std::string how_to_override;
  };
  struct CommandAnswer {
    int status = 200;  // as HTTP: 400 a bad override, 409 refused (overdue, or the sequencer's), ...
    std::string error;
    nlohmann::json extra = nlohmann::json::object();  // the error reply's other keys (state, overdue, problems)
    std::string state;                                // the new state when status is 200
  };
  CommandAnswer command_campaign(std::int64_t id, Command command, const CommandRequest& request);
  // The override of overdue reference equipment a campaign was started under (docs/api.md
  // "Campaigns": override_overdue), or null.
  nlohmann::json overdue_override_json(std::int64_t id);
  // GET /api/campaigns/{id}'s body, which the test report and the certificates are also made from.
  nlohmann::json detail_json(const CampaignRow& row);

 private:
  static const std::vector<Route>& routes();
  HttpReply login(const ApiRequest& request);
  HttpReply logout(const ApiRequest& request);
  HttpReply list_campaigns(const std::map<std::string, std::string>& query);
  HttpReply create_campaign(const ApiRequest& request);
  HttpReply validate_campaign(const ApiRequest& request);
  HttpReply plan_campaign(const ApiRequest& request);
  // An analysis job's answer when ready, else 202 with its progress.
  static HttpReply job_reply(const AnalysisJobs::Answer& answer);
  HttpReply campaign_detail(std::int64_t id);
  HttpReply campaign_model(std::int64_t id, const std::map<std::string, std::string>& query);
  HttpReply campaign_truth(std::int64_t id);
  HttpReply campaign_progress(std::int64_t id);
  // The recording bundle as a tar file, built once per run under DATA_DIR/exports/ by a job
  // (202 with its progress until it is there).
  HttpReply campaign_recording(std::int64_t id);
  HttpReply campaign_series(std::int64_t id, const std::map<std::string, std::string>& query);
  // allan, thermal, evaluation: computed from the run file once the run has ended, then cached.
  HttpReply campaign_analysis(std::int64_t id, const std::string& what);
  std::string run_path(const CampaignRow& row) const;
  HttpReply archived_recording_reply(const std::string& stand, const std::string& campaign);
  // 404 naming why when the campaign has no run file (never started, or not written yet).
  std::optional<HttpReply> no_recording(const CampaignRow& row, const std::string& prefix = "") const;
  HttpReply campaign_prompt(std::int64_t id, const ApiRequest& request, const Principal& who);
  HttpReply campaign_report(std::int64_t id, const std::map<std::string, std::string>& query);
  HttpReply campaign_command(std::int64_t id, const std::string& command, const ApiRequest& request,
                             const Principal& who);
  // The instruments overdue today (UTC) for a campaign a start would queue (none for a campaign in
  // another state: the sequencer answers that start itself).
  std::vector<InstrumentDue> overdue_for_start(std::int64_t id);
  nlohmann::json summary(const CampaignRow& row);
  // Campaign `id`'s row in the registry's units' calibrations after this API changed it (an
  // acceptance, a recalibration); a failure is logged.
  void record_calibration(std::int64_t id);
  // An operator's acceptance of a partial run as its unit's calibration.
  HttpReply campaign_accept(std::int64_t id, const ApiRequest& request, const Principal& who);
  // POST /api/campaigns/{id}/recalibrate: the run calibrated again from its recording with the
  // site's g as configured now, when its certificate in force states another; the certificate
  // that results supersedes it. A job: 202 with progress, asked again until 200.
  HttpReply campaign_recalibrate(std::int64_t id, const ApiRequest& request, const Principal& who);
  // Stores what the recalibration computed and issues the superseding certificate: the reply's body.
  nlohmann::json recalibrated(std::int64_t id, const std::string& who, const std::string& reason,
                              const Recalibration& r, double g_before_mps2);
  // GET /api/compare?a=ID&b=ID: two runs' models side by side (acceptance.hpp compare_json).
  HttpReply compare_campaigns(const std::map<std::string, std::string>& query);
  // GET /api/campaigns/{id}/certificate: the campaign's certificate in force (issued when the run
  // ended, when a partial run was accepted, or on this request for a run that counts as a
  // calibration and has none yet); GET /api/certificates/{number}: any one ever issued.
  HttpReply campaign_certificate(std::int64_t id);
  HttpReply certificate_by_number(const std::string& number);
  // PUT /api/certificates/{number}/page: the page as the browser printed it, stored once;
  // GET: those bytes.
  HttpReply store_certificate_page(const std::string& number, const ApiRequest& request, const Principal& who);
  HttpReply certificate_page(const std::string& number);
  nlohmann::json issued_json(const IssuedCertificateRow& c);
  // GET /api/alarms: those still needing someone (or all with ?all=1), of every campaign (or of
  // ?campaign=ID), newest first.
  HttpReply list_alarms(const std::map<std::string, std::string>& query);
  HttpReply list_audit(const std::map<std::string, std::string>& query);
  // POST /api/alarms/{id}/ack: who acknowledged it and when, once; broadcast.
  HttpReply acknowledge_alarm(const std::string& id_text, const Principal& who);
  // GET /api/campaigns/{id}/events.csv: the run's log with its alarms (alarms.hpp run_log_csv).
  HttpReply campaign_events_csv(std::int64_t id);
  void broadcast(const nlohmann::json& message);
  // PUT /api/limits: the whole limits file replaced by an operator.
  HttpReply replace_limits(const ApiRequest& request, const Principal& who);

  const DaemonConfig& config_;
  DaemonDb& db_;
  Registry& registry_;
  Sequencer& sequencer_;
  Auth& auth_;
  const AuditTrail& audit_;
  CertificateIssuer& certificates_;
  LimitsFile limits_;
  // A start is judged, its override recorded and the sequencer asked as one step: two starts of
  // one campaign never both record an override.
  std::mutex start_mutex_;
  nlohmann::json programs_;  // built once: the built-in programs do not change
  nlohmann::json chamber_map_;  // built once: the configured register map does not change
  nlohmann::json table_dialect_;  // built once, as the chamber map
  nlohmann::json truths_;         // the named simulated truths, built once, as the chamber map
  std::int64_t started_ms_;
  std::chrono::steady_clock::time_point started_;
  std::atomic<bool> shutting_down_{false};
  std::mutex export_mutex_;    // one recording export at a time
  // The IMU serial of each run file.
  std::mutex serial_mutex_;
  std::map<std::int64_t, std::string> serial_cache_;
  // Where analysis progress goes (the live WebSocket), once the HTTP server exists.
  std::mutex listener_mutex_;
  std::function<void(const nlohmann::json&)> event_listener_;
  // Last: its threads stop (and its running jobs are cancelled) before the rest goes.
  std::unique_ptr<AnalysisJobs> jobs_;
};

// The session id in a Cookie header, or empty.
std::string session_from_cookie(const std::string& cookie_header);
// A request target parsed (Boost.URL): the path as received, its segments percent-decoded (a
// trailing empty one dropped), and the query's parameters decoded ('+' is a space). Nothing for a
// malformed target (a bad percent escape).
struct Target {
  std::string path;
  std::vector<std::string> segments;
  std::map<std::string, std::string> query;
};
std::optional<Target> parse_target(const std::string& target);

}  // namespace imucal::daemon
