// The registry on a lab's PostgreSQL server (registry.hpp; issue 38): the stands of a production
// line share one. Its schema is versioned (table registry_schema) and migrated when a registry
// connects, under an advisory lock so that stands starting together migrate once. Certificate
// numbers come from the sequence certificate_sequence: two stands taking numbers at once never
// share one. Campaigns are named by the stand that ran them and their id there. One connection
// behind a mutex, connected again after the server went away; each call is short.
#pragma once

#include <functional>
#include <mutex>
#include <string>

#include "daemon/registry/registry.hpp"
#include "storage/postgres.hpp"

namespace imucal::daemon {

class PostgresRegistry final : public Registry {
 public:
  // 1: certificates (numbers, issued ones, pages), overdue overrides, the audit trail.
  // 2: registry_journal_applied, the writes a stand replayed from its journal (apply_once).
  // 3: calibration (each stand's campaigns that name a unit, the row as JSON) and limits (the
  // acceptance limits documents, the newest current; the older ones kept as their history).
  // 4: stand, the lab's stands and their last reported state (issue 38, the lab overview).
  static constexpr int kSchemaVersion = 5;
  // `conninfo`: registry.postgresql of the configuration (a libpq connection string). `stand`:
  // the name of the stand whose campaigns this registry records. Throws storage::pg::PgError when
  // the server cannot be reached, DbError when its schema is newer than this imucald knows.
  PostgresRegistry(const std::string& conninfo, std::string stand);

  std::string backend() const override { return "postgresql"; }
  const std::string& stand() const { return stand_; }
  std::int64_t next_certificate_sequence() override;
  std::int64_t max_certificate_sequence() override;
  // The number and the server's clock under one advisory lock (registry.hpp says why).
  CertificateNumber take_certificate_number() override;
  std::optional<CertificateRow> certificate(std::int64_t campaign_id) override;
  void insert_certificate(const CertificateRow& row) override;
  void insert_issued(const IssuedCertificateRow& row) override;
  std::optional<IssuedCertificateRow> issued(const std::string& number) override;
  std::optional<IssuedCertificateRow> current_issued(std::int64_t campaign_id) override;
  std::vector<IssuedCertificateRow> issued_history(std::int64_t campaign_id) override;
  std::vector<std::int64_t> campaigns_with_issued() override;
  bool insert_issued_page(const IssuedPageRow& row) override;
  std::optional<IssuedPageRow> issued_page(const std::string& number, bool with_html) override;
  void insert_overdue_override(const OverdueOverrideRow& row) override;
  void remove_overdue_override(std::int64_t campaign_id) override;
  std::optional<OverdueOverrideRow> overdue_override(std::int64_t campaign_id) override;
  AuditEntry append_audit(const std::string& actor, const std::string& action, const std::string& subject,
                          const std::string& details_json, std::optional<std::int64_t> t_ms) override;
  std::vector<AuditEntry> audit_entries(const AuditQuery& query) override;
  AuditChain audit_chain() override;
  void record_calibration(const CampaignRow& row) override;
  std::vector<CampaignRow> unit_campaigns(const std::optional<std::string>& serial) override;
  std::optional<std::string> limits_document() override;
  void put_limits_document(const std::string& document_json, const std::string& actor) override;

  // Stands: every stand of the lab, keyed by name (an upsert).
  void register_stand(const StandRow& row) override;
  bool report_stand_state(const std::string& name, const std::string& state_json, std::int64_t t_ms) override;
  std::vector<StandRow> stands() override;
  void put_user(const UserRow& row) override;
  bool remove_user(const std::string& name) override;
  std::vector<UserRow> users() override;

  // The schema version the server's registry has (after the migration of the constructor).
  int schema_version();

  // A write a stand journaled while the server was away (journaled_registry.hpp), applied with
  // its key: `write` (calls of this registry, on this thread) and the key (this stand, `journal`,
  // `seq`) are committed in one transaction, so a replay repeated after a crash applies nothing
  // twice. False, and nothing applied, when the key was recorded before.
  bool apply_once(const std::string& journal, std::int64_t seq, const std::function<void()>& write);

  // ---- A stand's registry moved in (registry_migration.hpp, imucal registry migrate) ----------
  // `work` (calls of this registry, on this thread) in one transaction, committed when `commit`,
  // else rolled back (a dry run): a migration that fails half way leaves nothing behind.
  void in_one_transaction(const std::function<void()>& work, bool commit);
  // The last number certificate_sequence handed out (0: none yet).
  std::int64_t last_certificate_sequence();
  // Moves certificate_sequence so that the next number is above `at_least` (never back); the new
  // last number. Not transactional (PostgreSQL's sequences never are): a rollback keeps it, which
  // leaves a gap, never a repeat.
  std::int64_t raise_certificate_sequence(std::int64_t at_least);

 private:
  void migrate();
  storage::pg::Connection& db();  // under mutex_
  std::string conninfo_;
  std::string stand_;
  // Recursive: apply_once's write calls this registry's own methods inside its transaction.
  std::recursive_mutex mutex_;
  storage::pg::Connection db_;
};

// The lab's audit trail and the head recorded beside it, read in one snapshot (stands appending
// meanwhile cannot make the head look ahead of the entries) and read only: no schema migration,
// nothing written. For `imucal audit verify --postgresql`. Throws storage::pg::PgError when the
// server cannot be reached, DbError when the database holds no registry or a newer schema.
struct RegistryAuditTrail {
  std::vector<AuditEntry> entries;
  std::optional<std::pair<std::int64_t, std::string>> head;
  std::vector<std::string> stands;  // each entry's stand, beside `entries`
  int schema_version = 0;
};
RegistryAuditTrail read_postgres_audit_trail(const std::string& conninfo);

}  // namespace imucal::daemon
