#include "daemon/registry/postgres_registry.hpp"

#include <stdexcept>
#include <utility>

#include "daemon/registry/calibrations.hpp"

namespace imucal::daemon {

namespace {

using storage::pg::Result;
using storage::pg::Transaction;

// Advisory locks of the registry (pg_advisory_xact_lock): one migration at a time, one audit
// append at a time (the chain is one line for every stand), one certificate number and its time
// at a time (take_certificate_number).
constexpr std::int64_t kMigrationLock = 380001;
constexpr std::int64_t kAuditLock = 380002;
constexpr std::int64_t kCertificateNumberLock = 380003;

// Version 1. The rules the SQLite database's triggers keep (an issued certificate, a page and the
// audit trail never change and are never deleted; superseded once) are kept by triggers here too.
constexpr const char* kSchema1 = R"sql(
CREATE SEQUENCE certificate_sequence AS BIGINT START 1;
CREATE TABLE setting(key TEXT PRIMARY KEY, value TEXT NOT NULL);
CREATE TABLE certificate(
  stand TEXT NOT NULL,
  campaign_id BIGINT NOT NULL,
  number TEXT NOT NULL UNIQUE,
  sequence BIGINT NOT NULL,
  issued_ms BIGINT NOT NULL,
  bench_json TEXT NOT NULL,
  PRIMARY KEY (stand, campaign_id));
CREATE TABLE issued_certificate(
  sequence BIGINT PRIMARY KEY,
  number TEXT NOT NULL UNIQUE,
  stand TEXT NOT NULL,
  campaign_id BIGINT NOT NULL,
  issued_ms BIGINT NOT NULL,
  content_json TEXT NOT NULL,
  content_sha256 TEXT NOT NULL,
  signed_json TEXT,
  supersedes TEXT,
  superseded_by TEXT,
  reason TEXT NOT NULL);
CREATE INDEX issued_certificate_campaign ON issued_certificate(stand, campaign_id);
CREATE TABLE issued_page(
  number TEXT PRIMARY KEY REFERENCES issued_certificate(number),
  html TEXT NOT NULL,
  sha256 TEXT NOT NULL,
  stored_ms BIGINT NOT NULL,
  stored_by TEXT NOT NULL);
CREATE TABLE overdue_override(
  stand TEXT NOT NULL,
  campaign_id BIGINT NOT NULL,
  t_ms BIGINT NOT NULL,
  overridden_by TEXT NOT NULL,
  reason TEXT NOT NULL,
  instruments_json TEXT NOT NULL,
  text TEXT NOT NULL,
  PRIMARY KEY (stand, campaign_id));
CREATE TABLE audit(
  seq BIGINT PRIMARY KEY,
  stand TEXT NOT NULL,
  t_ms BIGINT NOT NULL,
  actor TEXT NOT NULL,
  action TEXT NOT NULL,
  subject TEXT NOT NULL,
  details_json TEXT NOT NULL,
  prev_sha256 TEXT NOT NULL,
  sha256 TEXT NOT NULL);
CREATE FUNCTION imucal_refuse() RETURNS trigger LANGUAGE plpgsql AS
  $$ BEGIN RAISE EXCEPTION '%', TG_ARGV[0]; END $$;
CREATE TRIGGER issued_certificate_frozen
  BEFORE UPDATE OF sequence, number, stand, campaign_id, issued_ms, content_json, content_sha256, signed_json,
                   supersedes, reason ON issued_certificate
  FOR EACH ROW EXECUTE FUNCTION imucal_refuse('an issued certificate never changes: issue a new one that supersedes it');
CREATE TRIGGER issued_certificate_superseded_once
  BEFORE UPDATE OF superseded_by ON issued_certificate FOR EACH ROW WHEN (OLD.superseded_by IS NOT NULL)
  EXECUTE FUNCTION imucal_refuse('an issued certificate is superseded once');
CREATE TRIGGER issued_certificate_kept BEFORE DELETE ON issued_certificate
  FOR EACH ROW EXECUTE FUNCTION imucal_refuse('an issued certificate is never deleted');
CREATE TRIGGER issued_page_frozen BEFORE UPDATE OR DELETE ON issued_page
  FOR EACH ROW EXECUTE FUNCTION imucal_refuse('a stored certificate page never changes and is never deleted');
CREATE TRIGGER audit_append_only BEFORE UPDATE OR DELETE ON audit
  FOR EACH ROW EXECUTE FUNCTION imucal_refuse('the audit trail is appended only');
)sql";

// Version 2: the journaled writes each stand applied (journaled_registry.hpp), keyed by the
// stand, its journal (a journal started again after its file was lost numbers from 1 again) and
// the write's number in it.
constexpr const char* kSchema2 = R"sql(
CREATE TABLE registry_journal_applied(
  stand TEXT NOT NULL,
  journal TEXT NOT NULL,
  seq BIGINT NOT NULL,
  applied_ms BIGINT NOT NULL,
  PRIMARY KEY (stand, journal, seq));
)sql";

// Version 3: the units' calibrations, one row per (stand, campaign) replaced as it changes, its
// serial and creation time beside the row's JSON (calibrations.hpp) so that a unit's history is
// one indexed query in order; and the limits documents, appended (the newest is current).
constexpr const char* kSchema3 = R"sql(
CREATE TABLE calibration(
  stand TEXT NOT NULL,
  campaign_id BIGINT NOT NULL,
  serial TEXT NOT NULL,
  created_ms BIGINT NOT NULL,
  row_json TEXT NOT NULL,
  recorded_ms BIGINT NOT NULL,
  PRIMARY KEY (stand, campaign_id));
CREATE INDEX calibration_serial ON calibration(serial, created_ms);
CREATE TABLE limits(
  id BIGSERIAL PRIMARY KEY,
  document_json TEXT NOT NULL,
  stand TEXT NOT NULL,
  put_by TEXT NOT NULL,
  put_ms BIGINT NOT NULL);
CREATE TRIGGER limits_kept BEFORE UPDATE OR DELETE ON limits
  FOR EACH ROW EXECUTE FUNCTION imucal_refuse('a limits document is never changed: put a new one');
)sql";

// Version 4: the lab's stands (registry.hpp register_stand), one row each, keyed by name; its
// state is the heartbeat's last (volatile: replaced at each report).
constexpr const char* kSchemaStands = R"sql(
CREATE TABLE stand(
  name TEXT PRIMARY KEY,
  bench TEXT NOT NULL,
  url TEXT NOT NULL,
  version TEXT NOT NULL,
  heartbeat_ms BIGINT NOT NULL,
  registered_ms BIGINT NOT NULL,
  last_seen_ms BIGINT NOT NULL,
  state_json TEXT NOT NULL);
)sql";

// Version 5: the lab's accounts (registry.hpp put_user), one row each, keyed by name.
constexpr const char* kSchemaUsers = R"sql(
CREATE TABLE lab_user(
  name TEXT PRIMARY KEY,
  role TEXT NOT NULL CHECK (role IN ('viewer', 'operator')),
  password_hash TEXT NOT NULL,
  changed_ms BIGINT NOT NULL,
  changed_by TEXT NOT NULL);
)sql";

// The migrations in order: kMigrations[v - 1] takes a registry from version v - 1 to v.
constexpr const char* kMigrations[] = {kSchema1, kSchema2, kSchema3, kSchemaStands, kSchemaUsers};
static_assert(std::size(kMigrations) == PostgresRegistry::kSchemaVersion);

constexpr const char* kAuditHeadKey = "audit_head";  // setting: "SEQ SHA256" of the last entry, as in SQLite

#define IMUCAL_PG_ISSUED_SELECT                                                                            \
  "SELECT sequence, number, campaign_id, issued_ms, content_json, content_sha256, signed_json, supersedes, " \
  "superseded_by, reason FROM issued_certificate "
#define IMUCAL_PG_AUDIT_SELECT "SELECT seq, t_ms, actor, action, subject, details_json, prev_sha256, sha256 FROM audit "

IssuedCertificateRow issued_row(const Result& r, int i) {
  return IssuedCertificateRow{r.int64(i, 0),         r.text(i, 1),          r.int64(i, 2),
                              r.int64(i, 3),         r.text(i, 4),          r.text(i, 5),
                              r.optional_text(i, 6), r.optional_text(i, 7), r.optional_text(i, 8),
                              r.text(i, 9)};
}

std::vector<IssuedCertificateRow> issued_rows(const Result& r) {
  std::vector<IssuedCertificateRow> out;
  for (int i = 0; i < r.rows(); ++i) out.push_back(issued_row(r, i));
  return out;
}

// A write's own transaction, or none inside the one apply_once opened (its key and the write
// commit together).
class WriteScope {
 public:
  explicit WriteScope(storage::pg::Connection& connection) {
    if (!connection.in_transaction()) own_.emplace(connection);
  }
  void commit() {
    if (own_) own_->commit();
  }

 private:
  std::optional<Transaction> own_;
};

// The head recorded beside the trail ("SEQ SHA256"); a damaged value gives seq -1, which no trail
// matches (as the SQLite registry reads it).
std::optional<std::pair<std::int64_t, std::string>> read_audit_head(storage::pg::Connection& db) {
  const Result r = db.exec("SELECT value FROM setting WHERE key = $1", {kAuditHeadKey});
  if (r.rows() == 0) return std::nullopt;
  const std::string text = r.text(0, 0);
  const auto space = text.find(' ');
  try {
    if (space != std::string::npos)
      return std::make_pair(static_cast<std::int64_t>(std::stoll(text.substr(0, space))), text.substr(space + 1));
  } catch (const std::exception&) {
  }
  return std::make_pair(std::int64_t{-1}, text);
}

std::vector<AuditEntry> audit_rows(const Result& r) {
  std::vector<AuditEntry> out;
  for (int i = 0; i < r.rows(); ++i)
    out.push_back(AuditEntry{r.int64(i, 0), r.int64(i, 1), r.text(i, 2), r.text(i, 3), r.text(i, 4), r.text(i, 5),
                             r.text(i, 6), r.text(i, 7)});
  return out;
}

}  // namespace

PostgresRegistry::PostgresRegistry(const std::string& conninfo, std::string stand)
    : conninfo_(conninfo), stand_(std::move(stand)), db_(conninfo, "registry") {
  migrate();
}

// After the server went away (a restart, a network break), the next call connects again; the call
// that met the break failed with PgError::connection_lost.
storage::pg::Connection& PostgresRegistry::db() {
  if (!db_.ok()) db_ = storage::pg::Connection(conninfo_, "registry");
  return db_;
}

// A registry at the current version is only read: the stands' login role needs no right to create
// tables (docs/daemon.md "A lab of stands from scratch": the owner role migrates the schema).
void PostgresRegistry::migrate() {
  std::lock_guard lock(mutex_);
  Transaction txn(db());
  db().exec("SELECT pg_advisory_xact_lock($1)", {kMigrationLock});
  const bool exists = db().exec("SELECT to_regclass('registry_schema') IS NOT NULL").boolean(0, 0);
  const int version =
      exists ? static_cast<int>(db().exec("SELECT COALESCE(MAX(version), 0) FROM registry_schema").int64(0, 0)) : 0;
  if (version > kSchemaVersion)
    throw DbError("registry: the PostgreSQL server's registry has schema version " + std::to_string(version) +
                  ", newer than this imucald supports (" + std::to_string(kSchemaVersion) + ")");
  if (version == kSchemaVersion) return;  // nothing to write: the transaction ends empty
  try {
    if (!exists) db().exec("CREATE TABLE registry_schema(version INTEGER NOT NULL)");
    for (int v = version + 1; v <= kSchemaVersion; ++v) db().exec_script(kMigrations[v - 1]);
    db().exec("DELETE FROM registry_schema");
    db().exec("INSERT INTO registry_schema(version) VALUES ($1)", {kSchemaVersion});
  } catch (const storage::pg::PgError& e) {
    if (e.sqlstate() != "42501") throw;  // insufficient_privilege: said in the lab's words
    throw DbError("registry: the registry's schema is at version " + std::to_string(version) + " and this imucal needs " +
                  std::to_string(kSchemaVersion) + ", but its role may not change the schema (" + e.what() +
                  "): migrate it first as the registry's owner (imucal registry init --to 'OWNER CONNINFO')");
  }
  txn.commit();
}

int PostgresRegistry::schema_version() {
  std::lock_guard lock(mutex_);
  return static_cast<int>(db().exec("SELECT MAX(version) FROM registry_schema").int64(0, 0));
}

bool PostgresRegistry::apply_once(const std::string& journal, std::int64_t seq, const std::function<void()>& write) {
  std::lock_guard lock(mutex_);
  Transaction txn(db());
  // A key recorded already (by a replay that stopped before its journal was trimmed) leaves the
  // transaction with nothing in it; ON CONFLICT also waits for another transaction holding it.
  if (db().exec("INSERT INTO registry_journal_applied(stand, journal, seq, applied_ms) VALUES ($1, $2, $3, $4) "
                "ON CONFLICT DO NOTHING",
                {stand_, journal, seq, now_unix_ms()})
          .affected() == 0)
    return false;
  write();
  txn.commit();
  return true;
}

std::int64_t PostgresRegistry::next_certificate_sequence() {
  std::lock_guard lock(mutex_);
  return db().exec("SELECT nextval('certificate_sequence')").int64(0, 0);
}

// Issue 38's acceptance found the numbers of three stands issuing at once could state their
// issues out of order: nextval and then each stand's clock, two steps. Both are taken here under
// one lock, with one clock for every stand (the server's), so a later number is never an earlier
// issue. (A number is still taken whether or not its transaction commits: a sequence is not
// transactional, and a failed issue leaves a gap, as before.)
Registry::CertificateNumber PostgresRegistry::take_certificate_number() {
  std::lock_guard lock(mutex_);
  WriteScope txn(db());
  db().exec("SELECT pg_advisory_xact_lock($1)", {kCertificateNumberLock});
  const Result r = db().exec(
      "SELECT nextval('certificate_sequence'), FLOOR(EXTRACT(EPOCH FROM clock_timestamp()) * 1000)::BIGINT");
  txn.commit();
  return {r.int64(0, 0), r.int64(0, 1)};
}

std::int64_t PostgresRegistry::max_certificate_sequence() {
  std::lock_guard lock(mutex_);
  return db()
      .exec("SELECT GREATEST(COALESCE((SELECT MAX(sequence) FROM certificate), 0), "
            "COALESCE((SELECT MAX(sequence) FROM issued_certificate), 0))")
      .int64(0, 0);
}

std::optional<CertificateRow> PostgresRegistry::certificate(std::int64_t campaign_id) {
  std::lock_guard lock(mutex_);
  const Result r = db().exec(
      "SELECT campaign_id, number, sequence, issued_ms, bench_json FROM certificate WHERE stand = $1 AND campaign_id = $2",
      {stand_, campaign_id});
  if (r.rows() == 0) return std::nullopt;
  return CertificateRow{r.int64(0, 0), r.text(0, 1), r.int64(0, 2), r.int64(0, 3), r.text(0, 4)};
}

void PostgresRegistry::insert_certificate(const CertificateRow& row) {
  std::lock_guard lock(mutex_);
  db().exec("INSERT INTO certificate(stand, campaign_id, number, sequence, issued_ms, bench_json) "
           "VALUES ($1, $2, $3, $4, $5, $6)",
           {stand_, row.campaign_id, row.number, row.sequence, row.issued_ms, row.bench_json});
}

void PostgresRegistry::insert_issued(const IssuedCertificateRow& row) {
  std::lock_guard lock(mutex_);
  WriteScope txn(db());
  db().exec("INSERT INTO issued_certificate(sequence, number, stand, campaign_id, issued_ms, content_json, "
           "content_sha256, signed_json, supersedes, reason) VALUES ($1, $2, $3, $4, $5, $6, $7, $8, $9, $10)",
           {row.sequence, row.number, stand_, row.campaign_id, row.issued_ms, row.content_json, row.content_sha256,
            row.signed_json, row.supersedes, row.reason});
  if (row.supersedes)
    db().exec("UPDATE issued_certificate SET superseded_by = $1 WHERE number = $2", {row.number, *row.supersedes});
  txn.commit();
}

std::optional<IssuedCertificateRow> PostgresRegistry::issued(const std::string& number) {
  std::lock_guard lock(mutex_);
  const Result r = db().exec(IMUCAL_PG_ISSUED_SELECT "WHERE number = $1", {number});
  if (r.rows() == 0) return std::nullopt;
  return issued_row(r, 0);
}

std::optional<IssuedCertificateRow> PostgresRegistry::current_issued(std::int64_t campaign_id) {
  std::lock_guard lock(mutex_);
  const Result r = db().exec(IMUCAL_PG_ISSUED_SELECT
                            "WHERE stand = $1 AND campaign_id = $2 AND superseded_by IS NULL "
                            "ORDER BY sequence DESC LIMIT 1",
                            {stand_, campaign_id});
  if (r.rows() == 0) return std::nullopt;
  return issued_row(r, 0);
}

std::vector<IssuedCertificateRow> PostgresRegistry::issued_history(std::int64_t campaign_id) {
  std::lock_guard lock(mutex_);
  return issued_rows(
      db().exec(IMUCAL_PG_ISSUED_SELECT "WHERE stand = $1 AND campaign_id = $2 ORDER BY sequence", {stand_, campaign_id}));
}

std::vector<std::int64_t> PostgresRegistry::campaigns_with_issued() {
  std::lock_guard lock(mutex_);
  const Result r = db().exec(
      "SELECT DISTINCT campaign_id FROM issued_certificate WHERE stand = $1 AND superseded_by IS NULL "
      "ORDER BY campaign_id",
      {stand_});
  std::vector<std::int64_t> out;
  for (int i = 0; i < r.rows(); ++i) out.push_back(r.int64(i, 0));
  return out;
}

bool PostgresRegistry::insert_issued_page(const IssuedPageRow& row) {
  std::lock_guard lock(mutex_);
  // Two stands storing the same page at once: the first is kept, the second told so.
  return db()
             .exec("INSERT INTO issued_page(number, html, sha256, stored_ms, stored_by) VALUES ($1, $2, $3, $4, $5) "
                   "ON CONFLICT (number) DO NOTHING",
                   {row.number, row.html, row.sha256, row.stored_ms, row.stored_by})
             .affected() == 1;
}

std::optional<IssuedPageRow> PostgresRegistry::issued_page(const std::string& number, bool with_html) {
  std::lock_guard lock(mutex_);
  const Result r =
      db().exec(with_html ? "SELECT number, html, sha256, stored_ms, stored_by FROM issued_page WHERE number = $1"
                         : "SELECT number, '', sha256, stored_ms, stored_by FROM issued_page WHERE number = $1",
               {number});
  if (r.rows() == 0) return std::nullopt;
  return IssuedPageRow{r.text(0, 0), r.text(0, 1), r.text(0, 2), r.int64(0, 3), r.text(0, 4)};
}

void PostgresRegistry::insert_overdue_override(const OverdueOverrideRow& row) {
  std::lock_guard lock(mutex_);
  db().exec("INSERT INTO overdue_override(stand, campaign_id, t_ms, overridden_by, reason, instruments_json, text) "
           "VALUES ($1, $2, $3, $4, $5, $6, $7)",
           {stand_, row.campaign_id, row.t_ms, row.by, row.reason, row.instruments_json, row.text});
}

void PostgresRegistry::remove_overdue_override(std::int64_t campaign_id) {
  std::lock_guard lock(mutex_);
  db().exec("DELETE FROM overdue_override WHERE stand = $1 AND campaign_id = $2", {stand_, campaign_id});
}

std::optional<OverdueOverrideRow> PostgresRegistry::overdue_override(std::int64_t campaign_id) {
  std::lock_guard lock(mutex_);
  const Result r = db().exec(
      "SELECT campaign_id, t_ms, overridden_by, reason, instruments_json, text FROM overdue_override "
      "WHERE stand = $1 AND campaign_id = $2",
      {stand_, campaign_id});
  if (r.rows() == 0) return std::nullopt;
  return OverdueOverrideRow{r.int64(0, 0), r.int64(0, 1), r.text(0, 2), r.text(0, 3), r.text(0, 4), r.text(0, 5)};
}

AuditEntry PostgresRegistry::append_audit(const std::string& actor, const std::string& action,
                                          const std::string& subject, const std::string& details_json,
                                          std::optional<std::int64_t> t_ms) {
  std::lock_guard lock(mutex_);
  WriteScope txn(db());
  db().exec("SELECT pg_advisory_xact_lock($1)", {kAuditLock});  // one link at a time, from every stand
  std::optional<std::pair<std::int64_t, std::string>> previous;
  const Result last = db().exec("SELECT seq, sha256 FROM audit ORDER BY seq DESC LIMIT 1");
  if (last.rows() == 1) previous.emplace(last.int64(0, 0), last.text(0, 1));
  const AuditEntry e = next_audit_entry(previous, {t_ms.value_or(now_unix_ms()), actor, action, subject, details_json});
  db().exec("INSERT INTO audit(seq, stand, t_ms, actor, action, subject, details_json, prev_sha256, sha256) "
           "VALUES ($1, $2, $3, $4, $5, $6, $7, $8, $9)",
           {e.seq, stand_, e.t_ms, e.actor, e.action, e.subject, e.details_json, e.prev_sha256, e.sha256});
  db().exec("INSERT INTO setting(key, value) VALUES ($1, $2) ON CONFLICT (key) DO UPDATE SET value = EXCLUDED.value",
           {kAuditHeadKey, std::to_string(e.seq) + " " + e.sha256});
  txn.commit();
  return e;
}

std::vector<AuditEntry> PostgresRegistry::audit_entries(const AuditQuery& q) {
  std::lock_guard lock(mutex_);
  return audit_rows(db().exec(IMUCAL_PG_AUDIT_SELECT
                             "WHERE ($1::BIGINT IS NULL OR t_ms >= $1::BIGINT) AND ($2::BIGINT IS NULL OR t_ms <= $2::BIGINT) "
                             "AND ($3::TEXT = '' OR actor = $3::TEXT) "
                             "AND ($4::TEXT = '' OR starts_with(action, $4::TEXT)) "
                             "AND ($5::TEXT = '' OR subject = $5::TEXT) ORDER BY seq DESC LIMIT $6",
                             {q.from_ms, q.to_ms, q.actor, q.action_prefix, q.subject, q.limit}));
}

AuditChain PostgresRegistry::audit_chain() {
  std::lock_guard lock(mutex_);
  // REPEATABLE READ: both statements see one snapshot, whatever the other stands append meanwhile.
  // Inside a caller's transaction (a registry migration's) the reads are that transaction's.
  std::optional<Transaction> snapshot;
  if (!db().in_transaction()) {
    snapshot.emplace(db());
    db().exec("SET TRANSACTION ISOLATION LEVEL REPEATABLE READ, READ ONLY");
  }
  AuditChain out;
  out.entries = audit_rows(db().exec(IMUCAL_PG_AUDIT_SELECT "ORDER BY seq"));
  out.head = read_audit_head(db());
  if (snapshot) snapshot->commit();
  return out;
}

// ---- Stands (issue 38, the lab overview) ----

void PostgresRegistry::register_stand(const StandRow& row) {
  std::lock_guard lock(mutex_);
  db().exec("INSERT INTO stand(name, bench, url, version, heartbeat_ms, registered_ms, last_seen_ms, state_json) "
            "VALUES ($1, $2, $3, $4, $5, $6, $7, $8) ON CONFLICT (name) DO UPDATE SET bench = EXCLUDED.bench, "
            "url = EXCLUDED.url, version = EXCLUDED.version, heartbeat_ms = EXCLUDED.heartbeat_ms, "
            "registered_ms = EXCLUDED.registered_ms, last_seen_ms = EXCLUDED.last_seen_ms, "
            "state_json = EXCLUDED.state_json",
            {row.name, row.bench, row.url, row.version, row.heartbeat_ms, row.registered_ms, row.last_seen_ms,
             row.state_json});
}

bool PostgresRegistry::report_stand_state(const std::string& name, const std::string& state_json, std::int64_t t_ms) {
  std::lock_guard lock(mutex_);
  return db().exec("UPDATE stand SET state_json = $2, last_seen_ms = $3 WHERE name = $1", {name, state_json, t_ms})
             .affected() > 0;
}

std::vector<StandRow> PostgresRegistry::stands() {
  std::lock_guard lock(mutex_);
  const Result r = db().exec(
      "SELECT name, bench, url, version, heartbeat_ms, registered_ms, last_seen_ms, state_json FROM stand ORDER BY name");
  std::vector<StandRow> out;
  for (int i = 0; i < r.rows(); ++i)
    out.push_back(StandRow{r.text(i, 0), r.text(i, 1), r.text(i, 2), r.text(i, 3), r.int64(i, 4), r.int64(i, 5),
                           r.int64(i, 6), r.text(i, 7)});
  return out;
}

void PostgresRegistry::put_user(const UserRow& row) {
  std::lock_guard lock(mutex_);
  db().exec("INSERT INTO lab_user(name, role, password_hash, changed_ms, changed_by) VALUES ($1, $2, $3, $4, $5) "
            "ON CONFLICT (name) DO UPDATE SET role = EXCLUDED.role, password_hash = EXCLUDED.password_hash, "
            "changed_ms = EXCLUDED.changed_ms, changed_by = EXCLUDED.changed_by",
            {row.name, row.role, row.password_hash, row.changed_ms, row.changed_by});
}

bool PostgresRegistry::remove_user(const std::string& name) {
  std::lock_guard lock(mutex_);
  return db().exec("DELETE FROM lab_user WHERE name = $1", {name}).affected() > 0;
}

std::vector<UserRow> PostgresRegistry::users() {
  std::lock_guard lock(mutex_);
  const Result r = db().exec("SELECT name, role, password_hash, changed_ms, changed_by FROM lab_user ORDER BY name");
  std::vector<UserRow> out;
  for (int i = 0; i < r.rows(); ++i)
    out.push_back(UserRow{r.text(i, 0), r.text(i, 1), r.text(i, 2), r.int64(i, 3), r.text(i, 4)});
  return out;
}

void PostgresRegistry::record_calibration(const CampaignRow& row) {
  if (!row.imu_serial) throw std::invalid_argument("campaign " + std::to_string(row.id) + " names no unit: no calibration");
  std::lock_guard lock(mutex_);
  db().exec("INSERT INTO calibration(stand, campaign_id, serial, created_ms, row_json, recorded_ms) "
            "VALUES ($1, $2, $3, $4, $5, $6) ON CONFLICT (stand, campaign_id) DO UPDATE SET serial = EXCLUDED.serial, "
            "created_ms = EXCLUDED.created_ms, row_json = EXCLUDED.row_json, recorded_ms = EXCLUDED.recorded_ms",
            {stand_, row.id, *row.imu_serial, row.created_ms, campaign_row_json(row), now_unix_ms()});
}

// Oldest first as the SQLite registry orders them (creation, then the id), then by stand: two
// stands' campaigns created in the same millisecond keep one order.
std::vector<CampaignRow> PostgresRegistry::unit_campaigns(const std::optional<std::string>& serial) {
  std::lock_guard lock(mutex_);
  const Result r = db().exec(
      "SELECT stand, row_json FROM calibration WHERE ($1::TEXT IS NULL OR serial = $1::TEXT) "
      "ORDER BY created_ms, stand, campaign_id",
      {serial});
  std::vector<CampaignRow> out;
  for (int i = 0; i < r.rows(); ++i) {
    try {
      out.push_back(campaign_row_from_json(r.text(i, 1)));
    } catch (const std::exception& e) {
      throw DbError("registry: stand '" + r.text(i, 0) + "' recorded a calibration this imucald cannot read: " +
                    e.what());
    }
    out.back().stand = r.text(i, 0);
  }
  return out;
}

std::optional<std::string> PostgresRegistry::limits_document() {
  std::lock_guard lock(mutex_);
  const Result r = db().exec("SELECT document_json FROM limits ORDER BY id DESC LIMIT 1");
  if (r.rows() == 0) return std::nullopt;
  return r.text(0, 0);
}

void PostgresRegistry::put_limits_document(const std::string& document_json, const std::string& actor) {
  std::lock_guard lock(mutex_);
  db().exec("INSERT INTO limits(document_json, stand, put_by, put_ms) VALUES ($1, $2, $3, $4)",
            {document_json, stand_, actor, now_unix_ms()});
}

// ---- A stand's registry moved in (registry_migration.hpp) ----

void PostgresRegistry::in_one_transaction(const std::function<void()>& work, bool commit) {
  std::lock_guard lock(mutex_);
  Transaction txn(db());
  work();
  if (commit) txn.commit();
}

std::int64_t PostgresRegistry::last_certificate_sequence() {
  std::lock_guard lock(mutex_);
  return db().exec("SELECT CASE WHEN is_called THEN last_value ELSE 0 END FROM certificate_sequence").int64(0, 0);
}

std::int64_t PostgresRegistry::raise_certificate_sequence(std::int64_t at_least) {
  std::lock_guard lock(mutex_);
  if (at_least < 1) return last_certificate_sequence();
  // setval(n, true): the next nextval is n + 1. GREATEST with the last one taken: never back, even
  // past a number another stand took meanwhile.
  return db()
      .exec("SELECT setval('certificate_sequence', GREATEST($1::BIGINT, "
            "(SELECT CASE WHEN is_called THEN last_value ELSE 0 END FROM certificate_sequence)), true)",
            {at_least})
      .int64(0, 0);
}

RegistryAuditTrail read_postgres_audit_trail(const std::string& conninfo) {
  storage::pg::Connection db(conninfo, "registry");
  // One snapshot for the entries and the head, and nothing written whatever the statements.
  Transaction txn(db, true);
  db.exec("SET TRANSACTION READ ONLY");
  RegistryAuditTrail out;
  if (db.exec("SELECT to_regclass('registry_schema') IS NOT NULL").boolean(0, 0))
    out.schema_version = static_cast<int>(db.exec("SELECT COALESCE(MAX(version), 0) FROM registry_schema").int64(0, 0));
  if (out.schema_version == 0)
    throw DbError("registry: the database holds no imucal registry (no table registry_schema): is it the lab's?");
  if (out.schema_version > PostgresRegistry::kSchemaVersion)
    throw DbError("registry: the PostgreSQL server's registry has schema version " + std::to_string(out.schema_version) +
                  ", newer than this imucal supports (" + std::to_string(PostgresRegistry::kSchemaVersion) + ")");
  const Result r = db.exec("SELECT seq, t_ms, actor, action, subject, details_json, prev_sha256, sha256, stand "
                           "FROM audit ORDER BY seq");
  out.entries = audit_rows(r);
  for (int i = 0; i < r.rows(); ++i) out.stands.push_back(r.text(i, 8));
  out.head = read_audit_head(db);
  txn.commit();
  return out;
}

}  // namespace imucal::daemon
