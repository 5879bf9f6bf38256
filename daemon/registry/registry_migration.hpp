// A stand's registry moved from its own SQLite database into a lab's PostgreSQL registry (issue 38,
// `imucal registry migrate DATA_DIR --to CONNINFO`), and the lab's audit chain checked with the
// stands' chains it took in (`imucal audit verify --postgresql CONNINFO`).
//
// What moves: the certificate numbers of before issue 35, the issued certificates (superseded as
// they were) and their printed pages, the overdue overrides, the units' calibrations (the
// campaigns' rows), the limits document and the audit trail; each keyed in the lab by the stand's
// name (registry.stand) and its campaign ids, as the stand's imucald will write them from then on.
// All of it in one transaction: a conflict half way leaves the lab's registry as it was.
//
// The lab has one audit chain for every stand, so the stand's entries are appended to it in their
// order as new links (audit_chain.hpp's one rule), each carrying its origin in its details
// ("migrated_from": the stand, its seq, sha256 and prev_sha256 there), covered by the lab's hash:
// the stand's old chain stays checkable from the lab's alone (check_lab_audit_chain).
//
// Run twice, it copies nothing twice: a row the lab holds already, identical, is skipped and
// counted; one that differs is a conflict (an error naming it on both sides), never overwritten,
// but for a unit's calibration, which the stand's database always states last (recorded again).
#pragma once

#include <cstdint>
#include <optional>
#include <stdexcept>
#include <string>
#include <vector>

#include "daemon/db/audit_chain.hpp"
#include "daemon/db/daemon_db.hpp"

namespace imucal::daemon {

class PostgresRegistry;

// What a migration refuses (the stand's chain broken, a conflict with the lab's rows); the
// message names what and where. Nothing was copied.
class MigrationError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

struct StandRegistrySource {
  DaemonDb* db = nullptr;   // the stand's daemon database (DATA_DIR/imucald.db)
  std::string stand;        // its name in the lab (registry.stand of its configuration)
  std::string label;        // where it is, for messages and the audit entry (the data directory)
  // The stand's acceptance limits (its limits file, validated by the caller); none: no file.
  std::optional<std::string> limits_json;
  std::string actor;  // who migrates, for the lab's audit entry registry.migrated
};

struct MigrationCount {
  std::string what;  // "issued certificates", ...
  std::int64_t copied = 0;
  std::int64_t updated = 0;  // recorded again (a calibration the stand's database states newer)
  std::int64_t skipped = 0;  // in the lab already, identical
};

struct MigrationReport {
  bool dry_run = false;
  int lab_schema_version = 0;
  std::int64_t source_audit_entries = 0;  // the stand's chain, checked intact
  std::vector<MigrationCount> counts;     // in the order they are copied
  std::vector<std::string> notes;         // what was left as it was, and why
  std::int64_t highest_sequence = 0;      // the stand's highest certificate sequence number
  std::int64_t lab_sequence_before = 0;   // the lab's last certificate number before
  std::int64_t lab_sequence_after = 0;    // and after (a dry run: what it would be)
  std::int64_t first_lab_audit_seq = 0, last_lab_audit_seq = 0;  // the entries appended (0: none)

  std::int64_t copied() const;
  std::int64_t skipped() const;
  const MigrationCount& count(const std::string& what) const;  // throws std::out_of_range
  // The report as imucal prints it, one line each.
  std::vector<std::string> lines() const;
};

// Checks the stand's audit chain (MigrationError naming its first bad entry when it does not
// hold), then copies into `lab` (connected as source.stand: PostgresRegistry(conninfo,
// source.stand)). `dry_run`: everything is done and counted in a transaction that is rolled back,
// and the lab's certificate sequence is not moved. A failure of the lab's server propagates
// (storage::pg::PgError), nothing copied.
MigrationReport migrate_stand_registry(const StandRegistrySource& source, PostgresRegistry& lab, bool dry_run);

// ---- The migrated entries' origin ------------------------------------------------------------
// The details a stand's entry carries in the lab: its own details with "migrated_from" added (or,
// when they are not a JSON object, their text inside "migrated_from").
std::string migrated_details_json(const AuditEntry& original, const std::string& stand);
struct MigratedOrigin {
  std::string stand;
  AuditEntry original;  // as it was in the stand's chain: its seq, fields, links and hash
};
// The origin of a lab entry that was migrated; none for an entry written in the lab.
std::optional<MigratedOrigin> migrated_origin(const AuditEntry& lab_entry);

// The lab's chain (check_audit_chain over every entry and the head), then each stand's chain as
// it was migrated (its entries' origins, in order, checked by the same rule): the lab's first.
struct LabAuditCheck {
  AuditCheck lab;
  std::vector<std::pair<std::string, AuditCheck>> stands;  // by the stand's name, in the lab's order
  bool ok() const;
};
LabAuditCheck check_lab_audit_chain(const std::vector<AuditEntry>& entries,
                                    const std::optional<std::pair<std::int64_t, std::string>>& head);

}  // namespace imucal::daemon
