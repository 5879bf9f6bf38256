// imucal audit verify DATA_DIR | --postgresql CONNINFO: checks an audit trail offline by the one
// rule (daemon/db/audit_chain.hpp): each entry's hash, each link to the entry before, no gap, and
// the head the database recorded. DATA_DIR: a stand's own database; --postgresql: the lab's
// registry, one chain for every stand, and each stand's chain it took in with imucal registry
// migrate (registry_migration.hpp). Read only: nothing is written to either.
#include "cli/commands.hpp"

#include <cstdint>
#include <cstdio>
#include <string>
#include <filesystem>
#include <stdexcept>

#include "daemon/db/audit_chain.hpp"
#include "daemon/db/daemon_db.hpp"
#include "daemon/registry/postgres_registry.hpp"
#include "daemon/registry/registry_migration.hpp"

namespace imucal::cli {

int run_audit_verify(const std::string& data_dir) {
  const std::filesystem::path db_path = std::filesystem::path(data_dir) / "imucald.db";
  if (!std::filesystem::is_regular_file(db_path))
    throw std::runtime_error("no imucald database in '" + data_dir + "' (expected " + db_path.string() + ")");
  const daemon::AuditChain chain = daemon::read_audit_trail(db_path.string());
  const daemon::AuditCheck check = daemon::check_audit_chain(chain);
  std::printf("%s: %s\n", check.ok() ? "OK" : "FAILED", check.message.c_str());
  return check.ok() ? 0 : 1;
}

namespace {

// The stand that wrote entry `seq` of the lab's trail, as " (written by stand 'NAME')"; empty when
// it is not there. (No structured binding beside an optional here: clang 16's optional analysis
// crashes on one, README "The static check".)
std::string written_by(const daemon::RegistryAuditTrail& trail, std::int64_t seq) {
  for (std::size_t i = 0; i < trail.entries.size() && i < trail.stands.size(); ++i)
    if (trail.entries[i].seq == seq) return " (written by stand '" + trail.stands[i] + "')";
  return "";
}

}  // namespace

int run_audit_verify_postgresql(const std::string& conninfo) {
  daemon::RegistryAuditTrail trail;
  try {
    trail = daemon::read_postgres_audit_trail(conninfo);
  } catch (const storage::StorageError& e) {
    // The connection string is not printed: it may hold a password.
    throw std::runtime_error(std::string("the lab's registry (--postgresql): ") + e.what());
  }
  const daemon::LabAuditCheck check = daemon::check_lab_audit_chain(trail.entries, trail.head);
  const std::string where = written_by(trail, check.lab.first_bad.value_or(-1));
  std::printf("%s: the lab's %s%s\n", check.lab.ok() ? "OK" : "FAILED", check.lab.message.c_str(), where.c_str());
  for (const auto& stand : check.stands)
    std::printf("%s: stand '%s''s own chain, as migrated into the lab's: %s\n", stand.second.ok() ? "OK" : "FAILED",
                stand.first.c_str(), stand.second.message.c_str());
  return check.ok() ? 0 : 1;
}

}  // namespace imucal::cli
