// The lab's registry (issue 38): what outlives a stand's runs and is shared by the stands of a
// production line: certificate numbers and the certificates issued, their printed pages, the
// starts made with reference equipment past its due date, the audit trail with its hash chain, the
// units' calibrations and the acceptance limits.
// One interface, two implementations: the daemon's own SQLite database (SqliteRegistry, a stand
// alone, as before) and a lab's PostgreSQL server (PostgresRegistry, registry.postgresql in the
// configuration). The same suite runs against both (tests/daemon/test_registry.cpp).
//
// Each call is short and thread-safe; a failure of the store is a storage::StorageError.
// A campaign is named by its id on the stand that ran it (the stand's own database numbers them).
#pragma once

#include <cstdint>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "daemon/db/audit_chain.hpp"
#include "daemon/db/daemon_db.hpp"

namespace imucal::daemon {

class Registry {
 public:
  using AuditQuery = DaemonDb::AuditQuery;
  virtual ~Registry() = default;
  Registry() = default;
  Registry(const Registry&) = delete;
  Registry& operator=(const Registry&) = delete;

  // "sqlite" or "postgresql": what the daemon logs and GET /api/status may state.
  virtual std::string backend() const = 0;

  // Certificate numbering: the next site-wide sequence number, never one taken before (two
  // stands, or two threads, taking numbers at the same time never share one). A number taken and
  // not recorded (a crash, a failed issue) leaves a gap, never a repeat.
  virtual std::int64_t next_certificate_sequence() = 0;
  // The highest sequence number recorded (0: none), issued certificates and older numbers alike.
  virtual std::int64_t max_certificate_sequence() = 0;
  // A new number with the time of its issue, taken as one step: numbers follow the times the
  // certificates state. Here the number, then this stand's clock: one stand's issues are ordered
  // (the issuer takes them one at a time). A store several stands share takes both under one lock
  // of its own (PostgresRegistry: the server's clock; SqliteRegistry: the sequence file's lock,
  // never earlier than the last number's time): taken apart, stand a's number N and stand b's N+1
  // could state b's issue as the earlier, had a's thread been held up between its number and its
  // clock.
  struct CertificateNumber {
    std::int64_t sequence = 0;
    std::int64_t issued_ms = 0;
  };
  virtual CertificateNumber take_certificate_number() {
    const std::int64_t sequence = next_certificate_sequence();
    return {sequence, now_unix_ms()};
  }

  // A campaign's certificate number of before issue 35 (kept as it was issued).
  virtual std::optional<CertificateRow> certificate(std::int64_t campaign_id) = 0;
  virtual void insert_certificate(const CertificateRow& row) = 0;

  // Issued certificates (frozen at issue; only superseded_by is set, once, by the certificate that
  // supersedes it, in the same transaction as that one's insertion).
  virtual void insert_issued(const IssuedCertificateRow& row) = 0;
  virtual std::optional<IssuedCertificateRow> issued(const std::string& number) = 0;
  virtual std::optional<IssuedCertificateRow> current_issued(std::int64_t campaign_id) = 0;
  virtual std::vector<IssuedCertificateRow> issued_history(std::int64_t campaign_id) = 0;
  virtual std::vector<std::int64_t> campaigns_with_issued() = 0;
  // A certificate's printed page, stored once (false when one is stored already: it is kept).
  virtual bool insert_issued_page(const IssuedPageRow& row) = 0;
  virtual std::optional<IssuedPageRow> issued_page(const std::string& number, bool with_html) = 0;

  // The reference equipment's overdue overrides of campaigns' starts (one per campaign).
  virtual void insert_overdue_override(const OverdueOverrideRow& row) = 0;
  virtual void remove_overdue_override(std::int64_t campaign_id) = 0;
  virtual std::optional<OverdueOverrideRow> overdue_override(std::int64_t campaign_id) = 0;

  // The audit trail (audit_chain.hpp): appended with its link to the entry before and the head
  // recorded in one transaction, one chain for every writer of the store.
  virtual AuditEntry append_audit(const std::string& actor, const std::string& action, const std::string& subject,
                                  const std::string& details_json, std::optional<std::int64_t> t_ms) = 0;
  virtual std::vector<AuditEntry> audit_entries(const AuditQuery& query) = 0;
  // The whole trail and its recorded head read together (audit_chain.hpp: read apart, an entry
  // appended between the reads looks like entries deleted).
  virtual AuditChain audit_chain() = 0;
  std::vector<AuditEntry> audit_trail() { return audit_chain().entries; }

  // The units' calibrations (production/unit_registry.hpp reads them): a campaign's row as this
  // stand last recorded it (its end, an operator's acceptance, a recalibration), keyed by (stand,
  // campaign id): a later record of the same campaign replaces it. unit_campaigns: the rows that
  // name a unit (`serial`: that unit's only), every stand's, oldest first, each naming its stand.
  virtual void record_calibration(const CampaignRow& row) = 0;
  virtual std::vector<CampaignRow> unit_campaigns(const std::optional<std::string>& serial) = 0;

  // The acceptance limits (imucal-limits/1 as JSON text) the stands judge runs by: the current
  // document (none: no limits set yet), and a new one put by `actor` (validated by the caller,
  // production/limits_file.hpp). One document for every stand of the store.
  virtual std::optional<std::string> limits_document() = 0;
  virtual void put_limits_document(const std::string& document_json, const std::string& actor) = 0;

  // Whether the store answered when last asked, and how many writes wait on this stand's disk
  // for it (journaled_registry.hpp: a lab's server away); GET /api/status shows both. The
  // daemon's own database is always at hand.
  virtual bool reachable() const { return true; }
  virtual std::int64_t pending_writes() const { return 0; }

  // ---- Stands (issue 38, deliverable 2: the lab overview, GET /api/lab) ----------------------
  // Each imucald registers itself at its start (stand_heartbeat.hpp) and reports its state every
  // few seconds. A stand is keyed by its name: registering again replaces its row (a restart, a
  // new version, a new address). The SQLite registry knows one stand, itself.
  virtual void register_stand(const StandRow& row) = 0;
  // The stand's state (a JSON object's text) as of `t_ms`; false when no stand of that name is
  // registered (the lab's database was replaced under it: the caller registers again).
  virtual bool report_stand_state(const std::string& name, const std::string& state_json, std::int64_t t_ms) = 0;
  // Every registered stand, by name.
  virtual std::vector<StandRow> stands() = 0;
  // ---- end of stands ---------------------------------------------------------------------------

  // ---- The lab's accounts (issue 38, deliverable 1) ----------------------------------------------
  // Accounts that sign in with a password on every stand of the store (a stand's own configured
  // users besides; the configuration wins on a name both have: http/auth.hpp). put_user inserts or
  // replaces the account of that name; remove_user: false when there was none.
  virtual void put_user(const UserRow& row) = 0;
  virtual bool remove_user(const std::string& name) = 0;
  virtual std::vector<UserRow> users() = 0;
};

}  // namespace imucal::daemon
