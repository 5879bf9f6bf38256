// imucal audit verify DATA_DIR: checks the audit trail of an imucald data directory offline
// (daemon/db/audit_chain.hpp): each entry's hash, each link to the entry before, no gap, and the
// head the database recorded. Read only: the database is opened as a copy would be, nothing written.
#include "cli/commands.hpp"

#include <cstdio>
#include <filesystem>
#include <stdexcept>

#include "daemon/db/audit_chain.hpp"
#include "daemon/db/daemon_db.hpp"

namespace imucal::cli {

int run_audit_verify(const std::string& data_dir) {
  const std::filesystem::path db_path = std::filesystem::path(data_dir) / "imucald.db";
  if (!std::filesystem::is_regular_file(db_path))
    throw std::runtime_error("no imucald database in '" + data_dir + "' (expected " + db_path.string() + ")");
  const auto [entries, head] = daemon::read_audit_trail(db_path.string());
  const daemon::AuditCheck check = daemon::check_audit_chain(entries, head);
  std::printf("%s: %s\n", check.ok() ? "OK" : "FAILED", check.message.c_str());
  return check.ok() ? 0 : 1;
}

}  // namespace imucal::cli
