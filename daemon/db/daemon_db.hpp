// The daemon's own database (DATA_DIR/imucald.db, SQLite in WAL mode): campaigns with their run
// state, the queue, every state transition, run events (suspensions, redos, alarms), the alarms an
// operator acknowledges, and estimator progress. Frames live elsewhere, one storage::RunDb per run.
// Thread-safe: one connection (storage/sqlite.hpp) behind a mutex; every call is short.
#pragma once

#include <cstdint>
#include <exception>
#include <memory>
#include <mutex>
#include <optional>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

#include "daemon/db/audit_chain.hpp"
#include "daemon/db/run_state.hpp"
#include "storage/sqlite.hpp"

namespace imucal::daemon {

// What the daemon database itself refuses (a newer schema, a damaged file); SQLite's own failures
// are storage::sql::SqliteError. Both are storage::StorageError.
class DbError : public storage::StorageError {
 public:
  using storage::StorageError::StorageError;
};

struct CampaignRow {
  std::int64_t id = 0;
  std::string name;
  std::string spec_json;       // normalized campaign
  std::string program_label;
  double duration_s = 0.0;
  RunState state = RunState::Created;
  std::int64_t created_ms = 0;
  std::optional<std::int64_t> started_ms, ended_ms;
  std::optional<std::int64_t> checkpoint_segment;
  std::optional<double> checkpoint_s;
  double program_time_s = 0.0;
  std::int64_t frames = 0, lost_frames = 0, bad_frames = 0;
  std::string run_db;          // relative to the data directory; empty before the first start
  std::optional<std::string> model_json, results_json, estimators_json, error;
  std::optional<std::int64_t> queue_position;  // 0 = head
  // The unit it calibrates (campaign.imu; none for campaigns that name no unit).
  std::optional<std::string> imu_serial, imu_part_number;
  // Set when the run ends: true only when the whole program ran and the run ended done. A partial
  // run (stopped, aborted, failed) is no calibration of its unit unless an operator accepted it.
  std::optional<bool> complete;
  std::optional<std::string> accepted_reason, accepted_by;
  std::optional<std::int64_t> accepted_ms;
  // The stand that ran it (the lab's registry, issue 38: a unit's history gathers the stands'
  // calibrations, and campaign ids are numbered per stand). Empty as read from this stand's own
  // database: Registry::unit_campaigns names it.
  std::string stand;
};

// What identifies a campaign's unit in the registry (GET /api/imus).
struct CampaignUnit {
  std::string serial, part_number;
};

// The certificate number a campaign was given (issued once, then always the same).
struct CertificateRow {
  std::int64_t campaign_id = 0;
  std::string number;         // "LAB-2026-000123"
  std::int64_t sequence = 0;  // its site-wide sequence number (123)
  std::int64_t issued_ms = 0;
  std::string bench_json;     // certificate_bench_json() when it was issued
};

// A certificate as issued (issue 35, docs/api.md "Certificates"): its content is frozen when it is
// issued and never changes (the database refuses an UPDATE or a DELETE of it); a later certificate
// of the same campaign supersedes it, and only `superseded_by` is ever set, once.
struct IssuedCertificateRow {
  std::int64_t sequence = 0;  // the site-wide sequence number; PRIMARY KEY: issue order
  std::string number;         // "LAB-2026-000123"
  std::int64_t campaign_id = 0;
  std::int64_t issued_ms = 0;
  std::string content_json;    // the canonical JSON (imucal-certificate/1) that is hashed and signed
  std::string content_sha256;  // hex SHA-256 of content_json
  std::optional<std::string> signed_json;    // the signed envelope (imucal-signed/1) with the lab's key
  std::optional<std::string> supersedes;     // the number it replaces
  std::optional<std::string> superseded_by;  // the number that replaced it
  std::string reason;                        // why it was issued ("the run ended", "limits changed ...")
};

// A start an operator made while reference equipment was past its due date (issue 35): who, when,
// why, and the instruments as judged then. Kept with the run so that its certificate states it.
struct OverdueOverrideRow {
  std::int64_t campaign_id = 0;
  std::int64_t t_ms = 0;
  std::string by;
  std::string reason;
  std::string instruments_json;  // a JSON array: instrument, identity, serial, certificate, calibration_due
  std::string text;              // overdue_text() of them: "the rate table (...) was due for calibration on ..."
};

// A certificate's page as printed (HTML, self-contained), stored once.
struct IssuedPageRow {
  std::string number;
  std::string html;    // empty when read without it
  std::string sha256;  // hex SHA-256 of html
  std::int64_t stored_ms = 0;
  std::string stored_by;
};

struct TransitionRow {
  std::int64_t t_ms = 0;
  std::optional<RunState> from;
  RunState to = RunState::Created;
  std::string reason;
};

struct EventRow {
  std::int64_t t_ms = 0;
  std::string kind;
  std::optional<std::int64_t> segment;
  std::optional<double> program_time_s;
  std::string reason;
};

// An alarm (docs/api.md "Alarms"): raised with a run's serious condition, cleared when the condition
// ends (cleared_ms null while it is active), acknowledged once by an operator (null until then).
struct AlarmRow {
  std::int64_t id = 0;
  std::int64_t campaign_id = 0;
  std::string campaign_name;
  std::string severity;  // alarms.hpp: "major" or "minor"
  std::string source;    // what raised it: the event kind (suspended, alarm, error) or "interrupted"
  std::string message;
  std::optional<std::int64_t> segment;
  std::optional<double> program_time_s;
  std::int64_t raised_ms = 0;
  std::optional<std::int64_t> cleared_ms;
  std::optional<std::string> cleared_reason;
  std::optional<std::string> acknowledged_by;
  std::optional<std::int64_t> acknowledged_ms;
};

// A lab account (issue 38, registry.hpp put_user): it signs in with its password on every stand of
// the lab. Tokens stay in each stand's configuration (a script's token is a stand's).
struct UserRow {
  std::string name;
  std::string role;           // "viewer" or "operator"
  std::string password_hash;  // Argon2id as `imucal passwd` makes it (config/password_hash.hpp)
  std::int64_t changed_ms = 0;
  std::string changed_by;
};

// A stand of the lab (issue 38, registry.hpp): who it is, set when its imucald starts, and the
// state its heartbeat last reported (daemon/registry/stand_heartbeat.hpp).
struct StandRow {
  std::string name;                // registry_stand(config)
  std::string bench;               // the devices it drives (the configuration's `devices`)
  std::string url;                 // its own page, as other stands' browsers reach it
  std::string version;             // its imucald's
  std::int64_t heartbeat_ms = 0;   // how often it reports: GET /api/lab judges it online by this
  std::int64_t registered_ms = 0;  // its imucald's start
  std::int64_t last_seen_ms = 0;   // its last report (its own clock)
  std::string state_json = "{}";   // what it runs, its progress, its alarms (production/lab.hpp)
};

struct ProgressRow {
  std::string estimator;
  std::int64_t t_ms = 0;
  double program_time_s = 0.0;
  std::string json;
};

std::int64_t now_unix_ms();
std::string iso8601_utc(std::int64_t unix_ms);

// The audit trail and its recorded head from a daemon database file, read only (no migration, no
// lock on the data directory): for `imucal audit verify` beside a running imucald or on a copy.
AuditChain read_audit_trail(const std::string& path);

class DaemonDb {
 public:
  // 2: the unit (imu_serial, imu_part_number), `complete` and the operator's acceptance of a
  // partial run; databases of version 1 are migrated when opened.
  static constexpr int kSchemaVersion = 2;
  explicit DaemonDb(const std::string& path);
  ~DaemonDb();
  DaemonDb(const DaemonDb&) = delete;
  DaemonDb& operator=(const DaemonDb&) = delete;

  const std::string& path() const { return path_; }

  // Stores a checked campaign in state `created` (with its first transition). Returns its id.
  std::int64_t insert_campaign(const std::string& name, const std::string& spec_json, const std::string& program_label,
                               double duration_s, const std::string& reason,
                               const std::optional<CampaignUnit>& unit = std::nullopt);
  std::optional<CampaignRow> campaign(std::int64_t id);
  std::vector<CampaignRow> campaigns(std::int64_t limit);  // newest first
  // The campaigns that name a unit (one unit's with `serial`), oldest first.
  std::vector<CampaignRow> unit_campaigns(const std::optional<std::string>& serial);
  // Whether the run that ended ran its whole program (set before its final transition).
  void set_complete(std::int64_t id, bool complete);
  // An operator's acceptance of a partial run as a calibration of its unit.
  void accept(std::int64_t id, const std::string& reason, const std::string& who);

  // Changes the state and records the transition, in one transaction; sets started/ended times.
  // With `expected`, only when the current state is that one (returns false otherwise).
  bool set_state(std::int64_t id, RunState to, const std::string& reason,
                 std::optional<RunState> expected = std::nullopt);
  std::vector<TransitionRow> transitions(std::int64_t id);

  // Crash recovery at start-up: active runs become interrupted (an abort in progress completes
  // as aborted). Returns the ids changed.
  std::vector<std::int64_t> recover_after_restart(const std::string& reason);

  // The queue (FIFO; an interrupted run that is resumed goes to the head).
  void queue_push_back(std::int64_t id);
  void queue_push_front(std::int64_t id);
  void queue_remove(std::int64_t id);
  std::vector<std::int64_t> queue();

  void add_event(std::int64_t id, const std::string& kind, std::optional<std::int64_t> segment,
                 std::optional<double> program_time_s, const std::string& reason);
  std::vector<EventRow> events(std::int64_t id);

  void add_progress(std::int64_t id, const std::string& estimator, double program_time_s, const std::string& json);
  std::vector<ProgressRow> progress(std::int64_t id);

  void set_run_db(std::int64_t id, const std::string& relative_path);
  void update_run(std::int64_t id, double program_time_s, std::int64_t frames, std::int64_t lost_frames,
                  std::int64_t bad_frames);
  void set_checkpoint(std::int64_t id, std::int64_t segment, double t_s);
  void set_model(std::int64_t id, const std::string& model_json);
  void set_results(std::int64_t id, const std::string& results_json);
  void set_estimators(std::int64_t id, const std::string& estimators_json);
  void set_error(std::int64_t id, const std::string& error);

  std::optional<CertificateRow> certificate(std::int64_t campaign_id);
  void insert_certificate(const CertificateRow& row);
  // The highest certificate sequence number this database has recorded (0: none), issued
  // certificates and the numbers of before them alike.
  std::int64_t max_certificate_sequence();

  // Issued certificates. insert_issued stores `row` and, when it supersedes one, marks that one
  // superseded in the same transaction.
  void insert_issued(const IssuedCertificateRow& row);
  std::optional<IssuedCertificateRow> issued(const std::string& number);
  // The campaign's certificate in force (none superseding it), or none.
  std::optional<IssuedCertificateRow> current_issued(std::int64_t campaign_id);
  // Every certificate of the campaign, in issue order.
  std::vector<IssuedCertificateRow> issued_history(std::int64_t campaign_id);
  // A certificate's printed page: stored once (false when one is stored already: it is kept).
  bool insert_issued_page(const IssuedPageRow& row);
  std::optional<IssuedPageRow> issued_page(const std::string& number, bool with_html);
  // The campaigns that have a certificate in force.
  std::vector<std::int64_t> campaigns_with_issued();

  // The override of overdue reference equipment a campaign was started under (one per campaign:
  // only a campaign not yet started is judged, and it starts once). remove_overdue_override undoes
  // the record of a start the sequencer then refused.
  void insert_overdue_override(const OverdueOverrideRow& row);
  void remove_overdue_override(std::int64_t campaign_id);
  std::optional<OverdueOverrideRow> overdue_override(std::int64_t campaign_id);

  // Alarms. raise_alarm returns the new row. clear_alarms ends the active alarms of a campaign
  // (only those from `source` when given) and returns them as cleared.
  AlarmRow raise_alarm(std::int64_t campaign_id, const std::string& severity, const std::string& source,
                       const std::string& message, std::optional<std::int64_t> segment,
                       std::optional<double> program_time_s);
  std::vector<AlarmRow> clear_alarms(std::int64_t campaign_id, const std::optional<std::string>& source,
                                     const std::string& reason);
  enum class Ack { Acknowledged, NoSuchAlarm, AlreadyAcknowledged };
  // Records who acknowledged the alarm and when, once: a second acknowledgement changes nothing
  // (AlreadyAcknowledged, with the row as the first one left it). The row is there unless NoSuchAlarm.
  std::pair<Ack, std::optional<AlarmRow>> acknowledge_alarm(std::int64_t id, const std::string& who);
  std::optional<AlarmRow> alarm(std::int64_t id);
  // Oldest first. `campaign`: that campaign's only. `all` false: only those that still need
  // someone (active, or not acknowledged). At most `limit` (the newest ones).
  std::vector<AlarmRow> alarms(const std::optional<std::int64_t>& campaign, bool all, std::int64_t limit = 1000);

  // The audit trail (audit_chain.hpp). append_audit links the entry to the last one and records
  // the new head in one transaction; details_json must be a JSON object's text. `t_ms`: when it
  // happened (now when absent; an entry kept in memory through a full disk keeps its own time).
  AuditEntry append_audit(const std::string& actor, const std::string& action, const std::string& subject,
                          const std::string& details_json, std::optional<std::int64_t> t_ms = std::nullopt);
  struct AuditQuery {
    std::optional<std::int64_t> from_ms, to_ms;  // inclusive
    std::string actor, action_prefix, subject;   // empty: any
    std::int64_t limit = 1000;                   // newest first
  };
  std::vector<AuditEntry> audit_entries(const AuditQuery& query);
  // The whole trail in order and the head recorded beside it, one snapshot, for check_audit_chain.
  AuditChain audit_chain();
  std::vector<AuditEntry> audit_trail() { return audit_chain().entries; }

  // The stand table (issue 38): this daemon alone, the SQLite registry's (registry.hpp says what
  // each does). register_stand replaces any other row (a stand renamed is no other stand).
  void register_stand(const StandRow& row);
  bool report_stand_state(const std::string& name, const std::string& state_json, std::int64_t t_ms);
  std::vector<StandRow> stands();
  // The lab's accounts kept by the SQLite registry (registry.hpp says what each does).
  void put_user(const UserRow& row);
  bool remove_user(const std::string& name);
  std::vector<UserRow> users();

  std::optional<std::string> setting(const std::string& key);
  void set_setting(const std::string& key, const std::string& value);

 private:
  CampaignRow read_campaign_row(const storage::sql::Statement& stmt);
  std::string path_;
  std::mutex mutex_;
  storage::sql::Connection db_;
};

// Whether `e` is the daemon's database failing (full, locked too long, an I/O error, or damaged
// when `damaged` is set), or the registry's PostgreSQL server out of reach: a request that met it
// may be repeated once the database takes writes again, the service goes on. False for any other exception.
bool is_database_failure(const std::exception& e, bool* damaged = nullptr);

}  // namespace imucal::daemon
