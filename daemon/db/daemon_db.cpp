#include "daemon/db/daemon_db.hpp"

#include <chrono>
#include <cstdio>
#include <ctime>
#include <stdexcept>

#include "storage/postgres.hpp"

namespace imucal::daemon {

std::int64_t now_unix_ms() {
  return std::chrono::duration_cast<std::chrono::milliseconds>(std::chrono::system_clock::now().time_since_epoch())
      .count();
}

std::string iso8601_utc(std::int64_t unix_ms) {
  const std::time_t secs = static_cast<std::time_t>(unix_ms / 1000);
  std::tm tm{};
  gmtime_r(&secs, &tm);
  char buf[64];
  std::snprintf(buf, sizeof buf, "%04d-%02d-%02dT%02d:%02d:%02d.%03dZ", tm.tm_year + 1900, tm.tm_mon + 1, tm.tm_mday,
                tm.tm_hour, tm.tm_min, tm.tm_sec, static_cast<int>(unix_ms % 1000));
  return buf;
}

namespace {

const char* const kSchema = R"sql(
CREATE TABLE IF NOT EXISTS campaign(
  id INTEGER PRIMARY KEY,
  name TEXT NOT NULL,
  spec_json TEXT NOT NULL,
  program_label TEXT NOT NULL,
  duration_s REAL NOT NULL,
  state TEXT NOT NULL,
  created_ms INTEGER NOT NULL,
  started_ms INTEGER,
  ended_ms INTEGER,
  checkpoint_segment INTEGER,
  checkpoint_s REAL,
  program_time_s REAL NOT NULL DEFAULT 0,
  frames INTEGER NOT NULL DEFAULT 0,
  lost_frames INTEGER NOT NULL DEFAULT 0,
  bad_frames INTEGER NOT NULL DEFAULT 0,
  run_db TEXT NOT NULL DEFAULT '',
  model_json TEXT,
  results_json TEXT,
  estimators_json TEXT,
  error TEXT);
CREATE TABLE IF NOT EXISTS queue(
  position INTEGER PRIMARY KEY,
  campaign_id INTEGER NOT NULL UNIQUE REFERENCES campaign(id));
CREATE TABLE IF NOT EXISTS transition(
  id INTEGER PRIMARY KEY,
  campaign_id INTEGER NOT NULL REFERENCES campaign(id),
  t_ms INTEGER NOT NULL,
  from_state TEXT,
  to_state TEXT NOT NULL,
  reason TEXT NOT NULL);
CREATE INDEX IF NOT EXISTS transition_campaign ON transition(campaign_id);
CREATE TABLE IF NOT EXISTS event(
  id INTEGER PRIMARY KEY,
  campaign_id INTEGER NOT NULL REFERENCES campaign(id),
  t_ms INTEGER NOT NULL,
  kind TEXT NOT NULL,
  segment INTEGER,
  program_time_s REAL,
  reason TEXT NOT NULL);
CREATE INDEX IF NOT EXISTS event_campaign ON event(campaign_id);
CREATE TABLE IF NOT EXISTS progress(
  id INTEGER PRIMARY KEY,
  campaign_id INTEGER NOT NULL REFERENCES campaign(id),
  estimator TEXT NOT NULL,
  t_ms INTEGER NOT NULL,
  program_time_s REAL NOT NULL,
  json TEXT NOT NULL);
CREATE INDEX IF NOT EXISTS progress_campaign ON progress(campaign_id);
CREATE TABLE IF NOT EXISTS setting(key TEXT PRIMARY KEY, value TEXT NOT NULL);
-- A campaign's certificate number, issued once (docs/api.md "Certificates"); bench_json is what the
-- certificate states about the bench as configured then. A table of its own, created where
-- missing, so that databases of schema version 2 take it without a migration.
CREATE TABLE IF NOT EXISTS certificate(
  campaign_id INTEGER PRIMARY KEY REFERENCES campaign(id),
  number TEXT NOT NULL UNIQUE,
  sequence INTEGER NOT NULL,
  issued_ms INTEGER NOT NULL,
  bench_json TEXT NOT NULL
);
-- Alarms (docs/api.md "Alarms"): raised, cleared (NULL while active), acknowledged by whom and
-- when (NULL until then). Created where missing, as the certificate table, without a migration.
CREATE TABLE IF NOT EXISTS alarm(
  id INTEGER PRIMARY KEY,
  campaign_id INTEGER NOT NULL REFERENCES campaign(id),
  severity TEXT NOT NULL,
  source TEXT NOT NULL,
  message TEXT NOT NULL,
  segment INTEGER,
  program_time_s REAL,
  raised_ms INTEGER NOT NULL,
  cleared_ms INTEGER,
  cleared_reason TEXT,
  acknowledged_by TEXT,
  acknowledged_ms INTEGER
);
CREATE INDEX IF NOT EXISTS alarm_campaign ON alarm(campaign_id);
-- Certificates as issued (issue 35): the content is frozen at issue (canonical JSON, its SHA-256,
-- the signed envelope when the lab has a key) and the database itself refuses to change or delete
-- it; superseded_by is set once, when a later certificate replaces it. Created where missing.
CREATE TABLE IF NOT EXISTS issued_certificate(
  sequence INTEGER PRIMARY KEY,
  number TEXT NOT NULL UNIQUE,
  campaign_id INTEGER NOT NULL REFERENCES campaign(id),
  issued_ms INTEGER NOT NULL,
  content_json TEXT NOT NULL,
  content_sha256 TEXT NOT NULL,
  signed_json TEXT,
  supersedes TEXT,
  superseded_by TEXT,
  reason TEXT NOT NULL
);
CREATE INDEX IF NOT EXISTS issued_certificate_campaign ON issued_certificate(campaign_id);
CREATE TRIGGER IF NOT EXISTS issued_certificate_frozen
BEFORE UPDATE OF sequence, number, campaign_id, issued_ms, content_json, content_sha256, signed_json, supersedes, reason
ON issued_certificate
BEGIN SELECT RAISE(ABORT, 'an issued certificate never changes: issue a new one that supersedes it'); END;
CREATE TRIGGER IF NOT EXISTS issued_certificate_superseded_once
BEFORE UPDATE OF superseded_by ON issued_certificate WHEN OLD.superseded_by IS NOT NULL
BEGIN SELECT RAISE(ABORT, 'an issued certificate is superseded once'); END;
-- The audit trail (audit_chain.hpp): appended only; the triggers make an edit a deliberate act,
-- and the chain makes one that went past them visible (imucal audit verify).
CREATE TABLE IF NOT EXISTS audit(
  seq INTEGER PRIMARY KEY,
  t_ms INTEGER NOT NULL,
  actor TEXT NOT NULL,
  action TEXT NOT NULL,
  subject TEXT NOT NULL,
  details_json TEXT NOT NULL,
  prev_sha256 TEXT NOT NULL,
  sha256 TEXT NOT NULL
);
CREATE TRIGGER IF NOT EXISTS audit_append_only BEFORE UPDATE ON audit
BEGIN SELECT RAISE(ABORT, 'the audit trail is appended only'); END;
CREATE TRIGGER IF NOT EXISTS audit_kept BEFORE DELETE ON audit
BEGIN SELECT RAISE(ABORT, 'the audit trail is appended only'); END;
CREATE TRIGGER IF NOT EXISTS issued_certificate_kept
BEFORE DELETE ON issued_certificate
BEGIN SELECT RAISE(ABORT, 'an issued certificate is never deleted'); END;
-- A certificate's page as printed (issue 35): the bytes the lab's browser rendered from the issued
-- content when an operator first opened it, with their SHA-256; stored once and kept, so a reprint
-- years later, by a newer imucal, can be compared with what the customer received.
CREATE TABLE IF NOT EXISTS issued_page(
  number TEXT PRIMARY KEY REFERENCES issued_certificate(number),
  html TEXT NOT NULL,
  sha256 TEXT NOT NULL,
  stored_ms INTEGER NOT NULL,
  stored_by TEXT NOT NULL
);
CREATE TRIGGER IF NOT EXISTS issued_page_frozen BEFORE UPDATE ON issued_page
BEGIN SELECT RAISE(ABORT, 'a stored certificate page never changes'); END;
CREATE TRIGGER IF NOT EXISTS issued_page_kept BEFORE DELETE ON issued_page
BEGIN SELECT RAISE(ABORT, 'a stored certificate page is never deleted'); END;
-- A start with reference equipment past its due date, overridden by an operator (issue 35): kept
-- with the run so that its certificate states who overrode which instrument and why. Created
-- where missing, as the certificate table, without a migration.
CREATE TABLE IF NOT EXISTS overdue_override(
  campaign_id INTEGER PRIMARY KEY REFERENCES campaign(id),
  t_ms INTEGER NOT NULL,
  overridden_by TEXT NOT NULL,
  reason TEXT NOT NULL,
  instruments_json TEXT NOT NULL,
  text TEXT NOT NULL
);
-- This stand as the lab's registry knows it (issue 38, registry.hpp register_stand): one row,
-- itself, with the state its heartbeat last reported. Created where missing, without a migration,
-- as the certificate table; volatile, rewritten at each start.
CREATE TABLE IF NOT EXISTS stand(
  name TEXT PRIMARY KEY,
  bench TEXT NOT NULL,
  url TEXT NOT NULL,
  version TEXT NOT NULL,
  heartbeat_ms INTEGER NOT NULL,
  registered_ms INTEGER NOT NULL,
  last_seen_ms INTEGER NOT NULL,
  state_json TEXT NOT NULL
);
-- The lab's accounts (issue 38, registry.hpp put_user), created where missing, without a migration.
CREATE TABLE IF NOT EXISTS lab_user(
  name TEXT PRIMARY KEY,
  role TEXT NOT NULL CHECK (role IN ('viewer', 'operator')),
  password_hash TEXT NOT NULL,
  changed_ms INTEGER NOT NULL,
  changed_by TEXT NOT NULL
);
)sql";

using storage::sql::Statement;

constexpr const char* kCampaignColumns =
    "c.id, c.name, c.spec_json, c.program_label, c.duration_s, c.state, c.created_ms, c.started_ms, c.ended_ms, "
    "c.checkpoint_segment, c.checkpoint_s, c.program_time_s, c.frames, c.lost_frames, c.bad_frames, c.run_db, "
    "c.model_json, c.results_json, c.estimators_json, c.error, "
    "(SELECT COUNT(*) FROM queue q2 WHERE q2.position < q.position) AS queue_position, q.position IS NOT NULL, "
    "c.imu_serial, c.imu_part_number, c.complete, c.accepted_reason, c.accepted_by, c.accepted_ms";

// Version 1 -> 2, in the transaction that opens the database. A fresh database gets version 1's
// tables from kSchema and then these, so there is one path to the current schema. Runs that ended
// before version 2 count as complete when they ended done with the whole program's time.
const char* const kMigrationTo2 = R"sql(
ALTER TABLE campaign ADD COLUMN imu_serial TEXT;
ALTER TABLE campaign ADD COLUMN imu_part_number TEXT;
ALTER TABLE campaign ADD COLUMN complete INTEGER;
ALTER TABLE campaign ADD COLUMN accepted_reason TEXT;
ALTER TABLE campaign ADD COLUMN accepted_by TEXT;
ALTER TABLE campaign ADD COLUMN accepted_ms INTEGER;
CREATE INDEX IF NOT EXISTS campaign_imu ON campaign(imu_serial);
UPDATE campaign SET complete = (state = 'done' AND program_time_s >= duration_s - 1e-6)
  WHERE state IN ('done', 'failed', 'aborted');
)sql";

}  // namespace

DaemonDb::DaemonDb(const std::string& path)
    : path_(path), db_(path, storage::sql::Connection::Open::create, "daemon database") {
  // WAL + NORMAL: readers never block the writer, and a crash loses at most the last commits,
  // never the file.
  db_.exec("PRAGMA journal_mode=WAL");
  db_.exec("PRAGMA synchronous=NORMAL");
  db_.exec("PRAGMA foreign_keys=ON");
  const auto version = static_cast<int>(db_.query_int("PRAGMA user_version"));
  if (version > kSchemaVersion)
    throw DbError("daemon database '" + path + "' has schema version " + std::to_string(version) +
                  ", newer than this imucald supports (" + std::to_string(kSchemaVersion) + ")");
  {
    Statement s(db_, "PRAGMA quick_check");
    while (s.step())
      if (s.column_text(0) != "ok") throw DbError("daemon database '" + path + "' is damaged: " + s.column_text(0));
  }
  // The schema's statements create only what is missing, so on a current database the
  // transaction writes nothing and commits on a full disk too (imucald then starts, shows the full
  // disk and defers its writes) instead of refusing to start.
  storage::sql::Transaction txn(db_);
  db_.exec(kSchema);
  if (version < 2) db_.exec(kMigrationTo2);
  if (version != kSchemaVersion) db_.exec("PRAGMA user_version=" + std::to_string(kSchemaVersion));
  txn.commit();
}

DaemonDb::~DaemonDb() = default;


CampaignRow DaemonDb::read_campaign_row(const storage::sql::Statement& raw) {
  const Statement& s = raw;
  CampaignRow r;
  r.id = s.column_int64(0);
  r.name = s.column_text(1);
  r.spec_json = s.column_text(2);
  r.program_label = s.column_text(3);
  r.duration_s = s.column_double(4);
  r.state = parse_run_state(s.column_text(5)).value_or(RunState::Failed);
  r.created_ms = s.column_int64(6);
  r.started_ms = s.column_optional_int64(7);
  r.ended_ms = s.column_optional_int64(8);
  r.checkpoint_segment = s.column_optional_int64(9);
  r.checkpoint_s = s.column_optional_double(10);
  r.program_time_s = s.column_double(11);
  r.frames = s.column_int64(12);
  r.lost_frames = s.column_int64(13);
  r.bad_frames = s.column_int64(14);
  r.run_db = s.column_text(15);
  r.model_json = s.column_optional_text(16);
  r.results_json = s.column_optional_text(17);
  r.estimators_json = s.column_optional_text(18);
  r.error = s.column_optional_text(19);
  if (s.column_int64(21) != 0) r.queue_position = s.column_int64(20);
  r.imu_serial = s.column_optional_text(22);
  r.imu_part_number = s.column_optional_text(23);
  if (const auto c = s.column_optional_int64(24)) r.complete = *c != 0;
  r.accepted_reason = s.column_optional_text(25);
  r.accepted_by = s.column_optional_text(26);
  r.accepted_ms = s.column_optional_int64(27);
  return r;
}

std::int64_t DaemonDb::insert_campaign(const std::string& name, const std::string& spec_json,
                                       const std::string& program_label, double duration_s, const std::string& reason,
                                       const std::optional<CampaignUnit>& unit) {
  std::lock_guard lock(mutex_);
  storage::sql::Transaction txn(db_);
  const std::int64_t now = now_unix_ms();
  Statement s(db_,
         "INSERT INTO campaign(name, spec_json, program_label, duration_s, state, created_ms, imu_serial, "
         "imu_part_number) VALUES (?1,?2,?3,?4,?5,?6,?7,?8)");
  s.bind(1, name).bind(2, spec_json).bind(3, program_label).bind(4, duration_s);
  s.bind(5, std::string(to_string(RunState::Created))).bind(6, now);
  if (unit) {
    s.bind(7, unit->serial).bind(8, unit->part_number);
  } else {
    s.bind_null(7).bind_null(8);
  }
  s.run();
  const std::int64_t id = db_.last_insert_rowid();
  Statement t(db_, "INSERT INTO transition(campaign_id, t_ms, from_state, to_state, reason) VALUES (?1,?2,NULL,?3,?4)");
  t.bind(1, id).bind(2, now).bind(3, std::string(to_string(RunState::Created))).bind(4, reason);
  t.run();
  txn.commit();
  return id;
}

std::optional<CampaignRow> DaemonDb::campaign(std::int64_t id) {
  std::lock_guard lock(mutex_);
  const std::string sql = std::string("SELECT ") + kCampaignColumns +
                          " FROM campaign c LEFT JOIN queue q ON q.campaign_id = c.id WHERE c.id = ?1";
  Statement s(db_, sql.c_str());
  s.bind(1, id);
  if (!s.step()) return std::nullopt;
  return read_campaign_row(s);
}

std::vector<CampaignRow> DaemonDb::campaigns(std::int64_t limit) {
  std::lock_guard lock(mutex_);
  const std::string sql = std::string("SELECT ") + kCampaignColumns +
                          " FROM campaign c LEFT JOIN queue q ON q.campaign_id = c.id ORDER BY c.id DESC LIMIT ?1";
  Statement s(db_, sql.c_str());
  s.bind(1, limit);
  std::vector<CampaignRow> rows;
  while (s.step()) rows.push_back(read_campaign_row(s));
  return rows;
}

std::vector<CampaignRow> DaemonDb::unit_campaigns(const std::optional<std::string>& serial) {
  std::lock_guard lock(mutex_);
  const std::string sql = std::string("SELECT ") + kCampaignColumns +
                          " FROM campaign c LEFT JOIN queue q ON q.campaign_id = c.id WHERE c.imu_serial IS NOT NULL" +
                          (serial ? " AND c.imu_serial = ?1" : "") + " ORDER BY c.created_ms, c.id";
  Statement s(db_, sql.c_str());
  if (serial) s.bind(1, *serial);
  std::vector<CampaignRow> rows;
  while (s.step()) rows.push_back(read_campaign_row(s));
  return rows;
}

void DaemonDb::set_complete(std::int64_t id, bool complete) {
  std::lock_guard lock(mutex_);
  Statement s(db_, "UPDATE campaign SET complete = ?2 WHERE id = ?1");
  s.bind(1, id).bind(2, std::int64_t{complete ? 1 : 0});
  s.run();
}

void DaemonDb::accept(std::int64_t id, const std::string& reason, const std::string& who) {
  std::lock_guard lock(mutex_);
  Statement s(db_, "UPDATE campaign SET accepted_reason = ?2, accepted_by = ?3, accepted_ms = ?4 WHERE id = ?1");
  s.bind(1, id).bind(2, reason).bind(3, who).bind(4, now_unix_ms());
  s.run();
}

bool DaemonDb::set_state(std::int64_t id, RunState to, const std::string& reason, std::optional<RunState> expected) {
  std::lock_guard lock(mutex_);
  storage::sql::Transaction txn(db_);
  std::optional<RunState> from;
  {
    Statement s(db_, "SELECT state FROM campaign WHERE id = ?1");
    s.bind(1, id);
    if (!s.step()) return false;
    from = parse_run_state(s.column_text(0));
  }
  if (expected && from != expected) return false;
  // Every change, the operator's and the sequencer's, against the one table.
  if (from && !transition_allowed(*from, to)) throw InvalidTransition(id, *from, to);
  const std::int64_t now = now_unix_ms();
  {
    Statement s(db_,
           "UPDATE campaign SET state = ?2, "
           "started_ms = CASE WHEN ?2 = 'running' AND started_ms IS NULL THEN ?3 ELSE started_ms END, "
           "ended_ms = CASE WHEN ?2 IN ('done', 'failed', 'aborted') THEN ?3 ELSE ended_ms END WHERE id = ?1");
    s.bind(1, id).bind(2, std::string(to_string(to))).bind(3, now);
    s.run();
  }
  {
    Statement s(db_, "INSERT INTO transition(campaign_id, t_ms, from_state, to_state, reason) VALUES (?1,?2,?3,?4,?5)");
    s.bind(1, id).bind(2, now);
    if (from) {
      s.bind(3, std::string(to_string(*from)));
    } else {
      s.bind_null(3);
    }
    s.bind(4, std::string(to_string(to))).bind(5, reason);
    s.run();
  }
  if (is_final(to)) {
    Statement s(db_, "DELETE FROM queue WHERE campaign_id = ?1");
    s.bind(1, id);
    s.run();
  }
  txn.commit();
  return true;
}

std::vector<TransitionRow> DaemonDb::transitions(std::int64_t id) {
  std::lock_guard lock(mutex_);
  Statement s(db_, "SELECT t_ms, from_state, to_state, reason FROM transition WHERE campaign_id = ?1 ORDER BY id");
  s.bind(1, id);
  std::vector<TransitionRow> rows;
  while (s.step()) {
    TransitionRow r;
    r.t_ms = s.column_int64(0);
    if (!s.column_is_null(1)) r.from = parse_run_state(s.column_text(1));
    r.to = parse_run_state(s.column_text(2)).value_or(RunState::Failed);
    r.reason = s.column_text(3);
    rows.push_back(std::move(r));
  }
  return rows;
}

std::vector<std::int64_t> DaemonDb::recover_after_restart(const std::string& reason) {
  std::vector<std::pair<std::int64_t, RunState>> found;
  {
    std::lock_guard lock(mutex_);
    Statement s(db_, "SELECT id, state FROM campaign ORDER BY id");
    while (s.step()) {
      const auto state = parse_run_state(s.column_text(1));
      if (state && is_active(*state)) found.emplace_back(s.column_int64(0), *state);
    }
  }
  std::vector<std::int64_t> changed;
  for (const auto& [id, state] : found) {
    if (state == RunState::Aborting) {
      set_state(id, RunState::Aborted, "abort completed at start-up (" + reason + ")", state);
    } else {
      set_state(id, RunState::Interrupted, reason, state);
    }
    changed.push_back(id);
  }
  return changed;
}

void DaemonDb::queue_push_back(std::int64_t id) {
  std::lock_guard lock(mutex_);
  Statement s(db_, "INSERT OR IGNORE INTO queue(position, campaign_id) SELECT COALESCE(MAX(position), 0) + 1, ?1 FROM queue");
  s.bind(1, id);
  s.run();
}

void DaemonDb::queue_push_front(std::int64_t id) {
  std::lock_guard lock(mutex_);
  Statement s(db_, "INSERT OR IGNORE INTO queue(position, campaign_id) SELECT COALESCE(MIN(position), 0) - 1, ?1 FROM queue");
  s.bind(1, id);
  s.run();
}

void DaemonDb::queue_remove(std::int64_t id) {
  std::lock_guard lock(mutex_);
  Statement s(db_, "DELETE FROM queue WHERE campaign_id = ?1");
  s.bind(1, id);
  s.run();
}

std::vector<std::int64_t> DaemonDb::queue() {
  std::lock_guard lock(mutex_);
  Statement s(db_, "SELECT campaign_id FROM queue ORDER BY position");
  std::vector<std::int64_t> ids;
  while (s.step()) ids.push_back(s.column_int64(0));
  return ids;
}

void DaemonDb::add_event(std::int64_t id, const std::string& kind, std::optional<std::int64_t> segment,
                         std::optional<double> program_time_s, const std::string& reason) {
  std::lock_guard lock(mutex_);
  Statement s(db_,
         "INSERT INTO event(campaign_id, t_ms, kind, segment, program_time_s, reason) VALUES (?1,?2,?3,?4,?5,?6)");
  s.bind(1, id).bind(2, now_unix_ms()).bind(3, kind).bind(4, segment).bind(5, program_time_s).bind(6, reason);
  s.run();
}

std::vector<EventRow> DaemonDb::events(std::int64_t id) {
  std::lock_guard lock(mutex_);
  Statement s(db_, "SELECT t_ms, kind, segment, program_time_s, reason FROM event WHERE campaign_id = ?1 ORDER BY id");
  s.bind(1, id);
  std::vector<EventRow> rows;
  while (s.step()) rows.push_back({s.column_int64(0), s.column_text(1), s.column_optional_int64(2), s.column_optional_double(3), s.column_text(4)});
  return rows;
}

void DaemonDb::add_progress(std::int64_t id, const std::string& estimator, double program_time_s,
                            const std::string& json) {
  std::lock_guard lock(mutex_);
  Statement s(db_,
         "INSERT INTO progress(campaign_id, estimator, t_ms, program_time_s, json) VALUES (?1,?2,?3,?4,?5)");
  s.bind(1, id).bind(2, estimator).bind(3, now_unix_ms()).bind(4, program_time_s).bind(5, json);
  s.run();
}

std::vector<ProgressRow> DaemonDb::progress(std::int64_t id) {
  std::lock_guard lock(mutex_);
  Statement s(db_, "SELECT estimator, t_ms, program_time_s, json FROM progress WHERE campaign_id = ?1 ORDER BY id");
  s.bind(1, id);
  std::vector<ProgressRow> rows;
  while (s.step()) rows.push_back({s.column_text(0), s.column_int64(1), s.column_double(2), s.column_text(3)});
  return rows;
}

void DaemonDb::set_run_db(std::int64_t id, const std::string& relative_path) {
  std::lock_guard lock(mutex_);
  Statement s(db_, "UPDATE campaign SET run_db = ?2 WHERE id = ?1");
  s.bind(1, id).bind(2, relative_path);
  s.run();
}

void DaemonDb::update_run(std::int64_t id, double program_time_s, std::int64_t frames, std::int64_t lost_frames,
                          std::int64_t bad_frames) {
  std::lock_guard lock(mutex_);
  Statement s(db_,
         "UPDATE campaign SET program_time_s = ?2, frames = ?3, lost_frames = ?4, bad_frames = ?5 WHERE id = ?1");
  s.bind(1, id).bind(2, program_time_s).bind(3, frames).bind(4, lost_frames).bind(5, bad_frames);
  s.run();
}

void DaemonDb::set_checkpoint(std::int64_t id, std::int64_t segment, double t_s) {
  std::lock_guard lock(mutex_);
  Statement s(db_, "UPDATE campaign SET checkpoint_segment = ?2, checkpoint_s = ?3 WHERE id = ?1");
  s.bind(1, id).bind(2, segment).bind(3, t_s);
  s.run();
}

namespace {
void set_text_column(storage::sql::Connection& db, const char* sql, std::int64_t id, const std::string& v) {
  Statement s(db, sql);
  s.bind(1, id).bind(2, v);
  s.run();
}
}  // namespace

void DaemonDb::set_model(std::int64_t id, const std::string& model_json) {
  std::lock_guard lock(mutex_);
  set_text_column(db_, "UPDATE campaign SET model_json = ?2 WHERE id = ?1", id, model_json);
}
void DaemonDb::set_results(std::int64_t id, const std::string& results_json) {
  std::lock_guard lock(mutex_);
  set_text_column(db_, "UPDATE campaign SET results_json = ?2 WHERE id = ?1", id, results_json);
}
void DaemonDb::set_estimators(std::int64_t id, const std::string& estimators_json) {
  std::lock_guard lock(mutex_);
  set_text_column(db_, "UPDATE campaign SET estimators_json = ?2 WHERE id = ?1", id, estimators_json);
}
void DaemonDb::set_error(std::int64_t id, const std::string& error) {
  std::lock_guard lock(mutex_);
  set_text_column(db_, "UPDATE campaign SET error = ?2 WHERE id = ?1", id, error);
}

std::optional<std::string> DaemonDb::setting(const std::string& key) {
  std::lock_guard lock(mutex_);
  Statement s(db_, "SELECT value FROM setting WHERE key = ?1");
  s.bind(1, key);
  if (!s.step()) return std::nullopt;
  return s.column_text(0);
}

void DaemonDb::set_setting(const std::string& key, const std::string& value) {
  std::lock_guard lock(mutex_);
  Statement s(db_, "INSERT OR REPLACE INTO setting(key, value) VALUES (?1, ?2)");
  s.bind(1, key).bind(2, value);
  s.run();
}

std::optional<CertificateRow> DaemonDb::certificate(std::int64_t campaign_id) {
  std::lock_guard lock(mutex_);
  Statement s(db_, "SELECT campaign_id, number, sequence, issued_ms, bench_json FROM certificate WHERE campaign_id = ?1");
  s.bind(1, campaign_id);
  if (!s.step()) return std::nullopt;
  return CertificateRow{s.column_int64(0), s.column_text(1), s.column_int64(2), s.column_int64(3), s.column_text(4)};
}

void DaemonDb::insert_certificate(const CertificateRow& row) {
  std::lock_guard lock(mutex_);
  Statement s(db_,
         "INSERT INTO certificate(campaign_id, number, sequence, issued_ms, bench_json) VALUES (?1, ?2, ?3, ?4, ?5)");
  s.bind(1, row.campaign_id).bind(2, row.number).bind(3, row.sequence).bind(4, row.issued_ms).bind(5, row.bench_json);
  s.run();
}

std::int64_t DaemonDb::max_certificate_sequence() {
  std::lock_guard lock(mutex_);
  Statement s(db_,
              "SELECT MAX(COALESCE((SELECT MAX(sequence) FROM certificate), 0), "
              "COALESCE((SELECT MAX(sequence) FROM issued_certificate), 0))");
  return s.step() ? s.column_int64(0) : 0;
}

namespace {

// The columns issued_row and audit_row read, in their order: one list per table for every query
// (a macro, so that each query stays one string literal for Statement).
#define IMUCAL_ISSUED_SELECT                                                                              \
  "SELECT sequence, number, campaign_id, issued_ms, content_json, content_sha256, signed_json, supersedes, " \
  "superseded_by, reason FROM issued_certificate "
#define IMUCAL_AUDIT_SELECT "SELECT seq, t_ms, actor, action, subject, details_json, prev_sha256, sha256 FROM audit "

IssuedCertificateRow issued_row(const Statement& s) {
  return IssuedCertificateRow{s.column_int64(0),         s.column_text(1),          s.column_int64(2),
                              s.column_int64(3),         s.column_text(4),          s.column_text(5),
                              s.column_optional_text(6), s.column_optional_text(7), s.column_optional_text(8),
                              s.column_text(9)};
}

}  // namespace

void DaemonDb::insert_issued(const IssuedCertificateRow& row) {
  std::lock_guard lock(mutex_);
  storage::sql::Transaction txn(db_);
  {
    Statement s(db_, "INSERT INTO issued_certificate(sequence, number, campaign_id, issued_ms, content_json, "
                     "content_sha256, signed_json, supersedes, reason) VALUES (?1, ?2, ?3, ?4, ?5, ?6, ?7, ?8, ?9)");
    s.bind(1, row.sequence).bind(2, row.number).bind(3, row.campaign_id).bind(4, row.issued_ms);
    s.bind(5, row.content_json).bind(6, row.content_sha256).bind(7, row.signed_json).bind(8, row.supersedes);
    s.bind(9, row.reason);
    s.run();
  }
  if (row.supersedes) {
    Statement s(db_, "UPDATE issued_certificate SET superseded_by = ?1 WHERE number = ?2");
    s.bind(1, row.number).bind(2, *row.supersedes);
    s.run();
  }
  txn.commit();
}

void DaemonDb::insert_overdue_override(const OverdueOverrideRow& row) {
  std::lock_guard lock(mutex_);
  Statement s(db_, "INSERT INTO overdue_override(campaign_id, t_ms, overridden_by, reason, instruments_json, text) "
                   "VALUES (?1, ?2, ?3, ?4, ?5, ?6)");
  s.bind(1, row.campaign_id).bind(2, row.t_ms).bind(3, row.by).bind(4, row.reason).bind(5, row.instruments_json);
  s.bind(6, row.text);
  s.run();
}

void DaemonDb::remove_overdue_override(std::int64_t campaign_id) {
  std::lock_guard lock(mutex_);
  Statement s(db_, "DELETE FROM overdue_override WHERE campaign_id = ?1");
  s.bind(1, campaign_id);
  s.run();
}

std::optional<OverdueOverrideRow> DaemonDb::overdue_override(std::int64_t campaign_id) {
  std::lock_guard lock(mutex_);
  Statement s(db_, "SELECT campaign_id, t_ms, overridden_by, reason, instruments_json, text FROM overdue_override "
                   "WHERE campaign_id = ?1");
  s.bind(1, campaign_id);
  if (!s.step()) return std::nullopt;
  return OverdueOverrideRow{s.column_int64(0), s.column_int64(1), s.column_text(2),
                            s.column_text(3), s.column_text(4),  s.column_text(5)};
}

void DaemonDb::register_stand(const StandRow& row) {
  std::lock_guard lock(mutex_);
  storage::sql::Transaction txn(db_);
  {
    Statement others(db_, "DELETE FROM stand WHERE name <> ?1");
    others.bind(1, row.name);
    others.run();
  }
  Statement s(db_, "INSERT INTO stand(name, bench, url, version, heartbeat_ms, registered_ms, last_seen_ms, state_json) "
                   "VALUES (?1, ?2, ?3, ?4, ?5, ?6, ?7, ?8) ON CONFLICT(name) DO UPDATE SET bench = excluded.bench, "
                   "url = excluded.url, version = excluded.version, heartbeat_ms = excluded.heartbeat_ms, "
                   "registered_ms = excluded.registered_ms, last_seen_ms = excluded.last_seen_ms, "
                   "state_json = excluded.state_json");
  s.bind(1, row.name).bind(2, row.bench).bind(3, row.url).bind(4, row.version).bind(5, row.heartbeat_ms);
  s.bind(6, row.registered_ms).bind(7, row.last_seen_ms).bind(8, row.state_json);
  s.run();
  txn.commit();
}

bool DaemonDb::report_stand_state(const std::string& name, const std::string& state_json, std::int64_t t_ms) {
  std::lock_guard lock(mutex_);
  Statement s(db_, "UPDATE stand SET state_json = ?2, last_seen_ms = ?3 WHERE name = ?1");
  s.bind(1, name).bind(2, state_json).bind(3, t_ms);
  s.run();
  return db_.query_int("SELECT changes()") > 0;
}

std::vector<StandRow> DaemonDb::stands() {
  std::lock_guard lock(mutex_);
  Statement s(db_, "SELECT name, bench, url, version, heartbeat_ms, registered_ms, last_seen_ms, state_json FROM stand "
                   "ORDER BY name");
  std::vector<StandRow> out;
  while (s.step())
    out.push_back(StandRow{s.column_text(0), s.column_text(1), s.column_text(2), s.column_text(3), s.column_int64(4),
                           s.column_int64(5), s.column_int64(6), s.column_text(7)});
  return out;
}

void DaemonDb::put_user(const UserRow& row) {
  std::lock_guard lock(mutex_);
  Statement s(db_, "INSERT INTO lab_user(name, role, password_hash, changed_ms, changed_by) VALUES (?1, ?2, ?3, ?4, ?5) "
                   "ON CONFLICT(name) DO UPDATE SET role = excluded.role, password_hash = excluded.password_hash, "
                   "changed_ms = excluded.changed_ms, changed_by = excluded.changed_by");
  s.bind(1, row.name).bind(2, row.role).bind(3, row.password_hash).bind(4, row.changed_ms).bind(5, row.changed_by);
  s.run();
}

bool DaemonDb::remove_user(const std::string& name) {
  std::lock_guard lock(mutex_);
  Statement s(db_, "DELETE FROM lab_user WHERE name = ?1");
  s.bind(1, name);
  s.run();
  return db_.query_int("SELECT changes()") > 0;
}

std::vector<UserRow> DaemonDb::users() {
  std::lock_guard lock(mutex_);
  Statement s(db_, "SELECT name, role, password_hash, changed_ms, changed_by FROM lab_user ORDER BY name");
  std::vector<UserRow> out;
  while (s.step()) out.push_back(UserRow{s.column_text(0), s.column_text(1), s.column_text(2), s.column_int64(3), s.column_text(4)});
  return out;
}

bool DaemonDb::insert_issued_page(const IssuedPageRow& row) {
  std::lock_guard lock(mutex_);  // one imucald per data directory: nothing else inserts between
  {
    Statement stored(db_, "SELECT 1 FROM issued_page WHERE number = ?1");
    stored.bind(1, row.number);
    if (stored.step()) return false;
  }
  Statement s(db_, "INSERT INTO issued_page(number, html, sha256, stored_ms, stored_by) VALUES (?1, ?2, ?3, ?4, ?5)");
  s.bind(1, row.number).bind(2, row.html).bind(3, row.sha256).bind(4, row.stored_ms).bind(5, row.stored_by);
  s.run();
  return true;
}

std::optional<IssuedPageRow> DaemonDb::issued_page(const std::string& number, bool with_html) {
  std::lock_guard lock(mutex_);
  Statement s(db_, with_html ? "SELECT number, html, sha256, stored_ms, stored_by FROM issued_page WHERE number = ?1"
                             : "SELECT number, '', sha256, stored_ms, stored_by FROM issued_page WHERE number = ?1");
  s.bind(1, number);
  if (!s.step()) return std::nullopt;
  return IssuedPageRow{s.column_text(0), s.column_text(1), s.column_text(2), s.column_int64(3), s.column_text(4)};
}

std::optional<IssuedCertificateRow> DaemonDb::issued(const std::string& number) {
  std::lock_guard lock(mutex_);
  Statement s(db_, IMUCAL_ISSUED_SELECT "WHERE number = ?1");
  s.bind(1, number);
  if (!s.step()) return std::nullopt;
  return issued_row(s);
}

std::optional<IssuedCertificateRow> DaemonDb::current_issued(std::int64_t campaign_id) {
  std::lock_guard lock(mutex_);
  Statement s(db_, IMUCAL_ISSUED_SELECT
                 "WHERE campaign_id = ?1 AND superseded_by IS NULL ORDER BY sequence DESC LIMIT 1");
  s.bind(1, campaign_id);
  if (!s.step()) return std::nullopt;
  return issued_row(s);
}

std::vector<IssuedCertificateRow> DaemonDb::issued_history(std::int64_t campaign_id) {
  std::lock_guard lock(mutex_);
  Statement s(db_, IMUCAL_ISSUED_SELECT "WHERE campaign_id = ?1 ORDER BY sequence");
  s.bind(1, campaign_id);
  std::vector<IssuedCertificateRow> out;
  while (s.step()) out.push_back(issued_row(s));
  return out;
}

namespace {

constexpr const char* kAuditHeadKey = "audit_head";  // setting: "SEQ SHA256" of the last entry

// "SEQ SHA256"; a damaged value gives seq -1, which no trail matches.
std::pair<std::int64_t, std::string> parse_audit_head(const std::string& text) {
  const auto space = text.find(' ');
  if (space == std::string::npos) return {-1, text};
  try {
    return {static_cast<std::int64_t>(std::stoll(text.substr(0, space))), text.substr(space + 1)};
  } catch (const std::exception&) {
    return {-1, text};
  }
}

AuditEntry audit_row(const Statement& s) {
  return AuditEntry{s.column_int64(0), s.column_int64(1), s.column_text(2), s.column_text(3),
                    s.column_text(4),  s.column_text(5),  s.column_text(6), s.column_text(7)};
}

}  // namespace

AuditEntry DaemonDb::append_audit(const std::string& actor, const std::string& action, const std::string& subject,
                                  const std::string& details_json, std::optional<std::int64_t> t_ms) {
  std::lock_guard lock(mutex_);
  storage::sql::Transaction txn(db_);
  std::optional<std::pair<std::int64_t, std::string>> previous;
  {
    Statement last(db_, "SELECT seq, sha256 FROM audit ORDER BY seq DESC LIMIT 1");
    if (last.step()) previous.emplace(last.column_int64(0), last.column_text(1));
  }
  const AuditEntry e = next_audit_entry(previous, {t_ms.value_or(now_unix_ms()), actor, action, subject, details_json});
  {
    Statement s(db_, "INSERT INTO audit(seq, t_ms, actor, action, subject, details_json, prev_sha256, sha256) "
                     "VALUES (?1, ?2, ?3, ?4, ?5, ?6, ?7, ?8)");
    s.bind(1, e.seq).bind(2, e.t_ms).bind(3, e.actor).bind(4, e.action).bind(5, e.subject).bind(6, e.details_json);
    s.bind(7, e.prev_sha256).bind(8, e.sha256);
    s.run();
  }
  {
    Statement s(db_, "INSERT OR REPLACE INTO setting(key, value) VALUES (?1, ?2)");
    s.bind(1, std::string(kAuditHeadKey)).bind(2, std::to_string(e.seq) + " " + e.sha256);
    s.run();
  }
  txn.commit();
  return e;
}

namespace {

// One read transaction for the entries and the head: the daemon appends from other threads, and
// `imucal audit verify` reads beside a running imucald.
AuditChain read_audit_chain(storage::sql::Connection& db) {
  storage::sql::Transaction snapshot(db, storage::sql::Transaction::Lock::read);
  AuditChain out;
  {
    Statement s(db, IMUCAL_AUDIT_SELECT "ORDER BY seq");
    while (s.step()) out.entries.push_back(audit_row(s));
  }
  {
    Statement s(db, "SELECT value FROM setting WHERE key = ?1");
    s.bind(1, std::string(kAuditHeadKey));
    if (s.step()) out.head = parse_audit_head(s.column_text(0));
  }
  snapshot.commit();
  return out;
}

}  // namespace

AuditChain read_audit_trail(const std::string& path) {
  storage::sql::Connection db(path, storage::sql::Connection::Open::read_write, "daemon database");
  return read_audit_chain(db);
}

std::vector<AuditEntry> DaemonDb::audit_entries(const AuditQuery& q) {
  std::lock_guard lock(mutex_);
  Statement s(db_,
              IMUCAL_AUDIT_SELECT
              "WHERE (?1 IS NULL OR t_ms >= ?1) AND (?2 IS NULL OR t_ms <= ?2) AND (?3 = '' OR actor = ?3) "
              "AND (?4 = '' OR substr(action, 1, length(?4)) = ?4) AND (?5 = '' OR subject = ?5) "
              "ORDER BY seq DESC LIMIT ?6");
  s.bind(1, q.from_ms).bind(2, q.to_ms).bind(3, q.actor).bind(4, q.action_prefix).bind(5, q.subject).bind(6, q.limit);
  std::vector<AuditEntry> out;
  while (s.step()) out.push_back(audit_row(s));
  return out;
}

AuditChain DaemonDb::audit_chain() {
  std::lock_guard lock(mutex_);
  return read_audit_chain(db_);
}

std::vector<std::int64_t> DaemonDb::campaigns_with_issued() {
  std::lock_guard lock(mutex_);
  Statement s(db_, "SELECT DISTINCT campaign_id FROM issued_certificate WHERE superseded_by IS NULL ORDER BY campaign_id");
  std::vector<std::int64_t> out;
  while (s.step()) out.push_back(s.column_int64(0));
  return out;
}

namespace {

constexpr const char* kAlarmColumns =
    "a.id, a.campaign_id, COALESCE(c.name, ''), a.severity, a.source, a.message, a.segment, a.program_time_s, "
    "a.raised_ms, a.cleared_ms, a.cleared_reason, a.acknowledged_by, a.acknowledged_ms "
    "FROM alarm a LEFT JOIN campaign c ON c.id = a.campaign_id";

AlarmRow read_alarm_row(const Statement& s) {
  AlarmRow r;
  r.id = s.column_int64(0);
  r.campaign_id = s.column_int64(1);
  r.campaign_name = s.column_text(2);
  r.severity = s.column_text(3);
  r.source = s.column_text(4);
  r.message = s.column_text(5);
  r.segment = s.column_optional_int64(6);
  r.program_time_s = s.column_optional_double(7);
  r.raised_ms = s.column_int64(8);
  r.cleared_ms = s.column_optional_int64(9);
  r.cleared_reason = s.column_optional_text(10);
  r.acknowledged_by = s.column_optional_text(11);
  r.acknowledged_ms = s.column_optional_int64(12);
  return r;
}

std::optional<AlarmRow> select_alarm(storage::sql::Connection& db, std::int64_t id) {
  const std::string sql = std::string("SELECT ") + kAlarmColumns + " WHERE a.id = ?1";
  Statement s(db, sql.c_str());
  s.bind(1, id);
  if (!s.step()) return std::nullopt;
  return read_alarm_row(s);
}

// An alarm this connection has just written, under the lock and in the same transaction: it is
// there, or the database is not what this code believes (a logic error, not a missing row).
AlarmRow written_alarm(storage::sql::Connection& db, std::int64_t id) {
  auto row = select_alarm(db, id);
  if (!row) throw std::logic_error("alarm " + std::to_string(id) + " is not in the database right after it was written");
  return std::move(*row);
}

}  // namespace

AlarmRow DaemonDb::raise_alarm(std::int64_t campaign_id, const std::string& severity, const std::string& source,
                               const std::string& message, std::optional<std::int64_t> segment,
                               std::optional<double> program_time_s) {
  std::lock_guard lock(mutex_);
  Statement s(db_,
         "INSERT INTO alarm(campaign_id, severity, source, message, segment, program_time_s, raised_ms) "
         "VALUES (?1,?2,?3,?4,?5,?6,?7)");
  s.bind(1, campaign_id).bind(2, severity).bind(3, source).bind(4, message).bind(5, segment).bind(6, program_time_s);
  s.bind(7, now_unix_ms());
  s.run();
  return written_alarm(db_, db_.last_insert_rowid());
}

std::vector<AlarmRow> DaemonDb::clear_alarms(std::int64_t campaign_id, const std::optional<std::string>& source,
                                             const std::string& reason) {
  std::lock_guard lock(mutex_);
  storage::sql::Transaction txn(db_);
  std::vector<std::int64_t> ids;
  {
    Statement s(db_,
           "SELECT id FROM alarm WHERE campaign_id = ?1 AND cleared_ms IS NULL AND (?2 IS NULL OR source = ?2) "
           "ORDER BY id");
    s.bind(1, campaign_id).bind(2, source);
    while (s.step()) ids.push_back(s.column_int64(0));
  }
  const std::int64_t now = now_unix_ms();
  std::vector<AlarmRow> cleared;
  for (const std::int64_t id : ids) {
    Statement u(db_, "UPDATE alarm SET cleared_ms = ?2, cleared_reason = ?3 WHERE id = ?1");
    u.bind(1, id).bind(2, now).bind(3, reason);
    u.run();
    cleared.push_back(written_alarm(db_, id));
  }
  txn.commit();
  return cleared;
}

std::pair<DaemonDb::Ack, std::optional<AlarmRow>> DaemonDb::acknowledge_alarm(std::int64_t id, const std::string& who) {
  std::lock_guard lock(mutex_);
  storage::sql::Transaction txn(db_);
  const auto before = select_alarm(db_, id);
  if (!before) return {Ack::NoSuchAlarm, std::nullopt};
  if (before->acknowledged_ms) return {Ack::AlreadyAcknowledged, before};
  Statement u(db_, "UPDATE alarm SET acknowledged_by = ?2, acknowledged_ms = ?3 WHERE id = ?1");
  u.bind(1, id).bind(2, who).bind(3, now_unix_ms());
  u.run();
  auto after = written_alarm(db_, id);
  txn.commit();
  return {Ack::Acknowledged, std::move(after)};
}

std::optional<AlarmRow> DaemonDb::alarm(std::int64_t id) {
  std::lock_guard lock(mutex_);
  return select_alarm(db_, id);
}

std::vector<AlarmRow> DaemonDb::alarms(const std::optional<std::int64_t>& campaign, bool all, std::int64_t limit) {
  std::lock_guard lock(mutex_);
  // The newest `limit`, handed back oldest first.
  const std::string sql = std::string("SELECT * FROM (SELECT ") + kAlarmColumns +
                          " WHERE (?1 IS NULL OR a.campaign_id = ?1)" +
                          (all ? "" : " AND (a.cleared_ms IS NULL OR a.acknowledged_ms IS NULL)") +
                          " ORDER BY a.id DESC LIMIT ?2) ORDER BY 1";
  Statement s(db_, sql.c_str());
  s.bind(1, campaign).bind(2, limit);
  std::vector<AlarmRow> rows;
  while (s.step()) rows.push_back(read_alarm_row(s));
  return rows;
}

bool is_database_failure(const std::exception& e, bool* damaged) {
  // The registry's PostgreSQL server out of reach (storage/postgres.hpp): the request may be
  // repeated once it is back; a refusal of the server (a constraint) is no such failure.
  if (const auto* pg = dynamic_cast<const storage::pg::PgError*>(&e)) {
    if (damaged != nullptr) *damaged = false;
    return pg->connection_lost();
  }
  const auto* sqlite = dynamic_cast<const storage::sql::SqliteError*>(&e);
  if (sqlite == nullptr) return false;
  if (damaged != nullptr) *damaged = sqlite->kind() == storage::sql::SqliteError::Kind::damaged;
  return true;
}

}  // namespace imucal::daemon
