// imucal registry init --to CONNINFO: the lab's registry's schema created or migrated (by its owner
// role; the stands' role only reads and writes rows).
// imucal registry migrate DATA_DIR --to CONNINFO: a stand's registry (its own SQLite database)
// moved into the lab's PostgreSQL registry (daemon/registry/registry_migration.hpp), with imucald
// stopped on that data directory. Errors name what is wrong and where: the data directory, the
// stand's chain, the server (--to), a conflict with the lab's rows.
#include "cli/commands.hpp"

#include <fcntl.h>
#include <sys/file.h>
#include <unistd.h>

#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <memory>
#include <optional>
#include <sstream>
#include <stdexcept>

#include <nlohmann/json.hpp>

#include "daemon/config/config.hpp"
#include "daemon/db/daemon_db.hpp"
#include "daemon/production/acceptance.hpp"
#include "daemon/registry/postgres_registry.hpp"
#include "daemon/registry/registry_migration.hpp"

namespace imucal::cli {

namespace fs = std::filesystem;

namespace {

// imucald's own lock on its data directory, held while the migration reads it: a running imucald
// would go on writing the registry the migration is moving (its journal, its trail).
class DataDirLock {
 public:
  explicit DataDirLock(const fs::path& data_dir) {
    const std::string path = (data_dir / "imucald.lock").string();
    fd_ = ::open(path.c_str(), O_RDWR | O_CREAT | O_CLOEXEC, 0600);
    if (fd_ < 0) throw std::runtime_error("cannot open " + path + " to lock the data directory");
    if (::flock(fd_, LOCK_EX | LOCK_NB) != 0) {
      ::close(fd_);
      throw std::runtime_error("an imucald is running on the data directory '" + data_dir.string() + "' (it holds " +
                               path + "): stop it before moving its registry");
    }
  }
  ~DataDirLock() { ::close(fd_); }
  DataDirLock(const DataDirLock&) = delete;
  DataDirLock& operator=(const DataDirLock&) = delete;

 private:
  int fd_ = -1;
};

// The stand's name and its limits file as its imucald takes them: from its configuration when one
// is given, else the host's name and DATA_DIR/limits.json (imucald's defaults); --stand and
// --limits override.
struct StandSettings {
  std::string stand;
  fs::path limits;
};

StandSettings stand_settings(const RegistryMigrateArgs& a) {
  daemon::DaemonConfig config;
  if (!a.config_file.empty()) config = daemon::load_config_file(a.config_file);
  if (!a.stand.empty()) config.registry.stand = a.stand;
  StandSettings out;
  out.stand = daemon::registry_stand(config);
  const fs::path limits = a.limits_file.empty() ? fs::path(config.limits_file) : fs::path(a.limits_file);
  out.limits = limits.is_absolute() || !a.limits_file.empty() ? limits : fs::path(a.data_dir) / limits;
  return out;
}

// The stand's limits document in the form imucald stores it (PUT /api/limits), validated: none
// when there is no file.
std::optional<std::string> read_limits(const fs::path& path) {
  std::error_code ec;
  if (!fs::exists(path, ec)) return std::nullopt;
  std::ifstream in(path);
  std::stringstream text;
  text << in.rdbuf();
  if (!in) throw std::runtime_error("cannot read the limits file " + path.string());
  try {
    return daemon::limits_to_json(daemon::limits_from_json(nlohmann::json::parse(text.str()))).dump(2) + "\n";
  } catch (const std::exception& e) {
    throw std::runtime_error("the limits file " + path.string() + " is not imucal-limits/1: " + e.what());
  }
}

std::string login_name(const std::string& given) {
  if (!given.empty()) return given;
  const char* user = std::getenv("USER");
  return user != nullptr && *user != '\0' ? user : "imucal";
}

// The lab's registry, connected as the stand; the server's and the schema's refusals named as
// --to's (the connection string is not printed: it may hold a password).
std::unique_ptr<daemon::PostgresRegistry> connect_lab(const std::string& conninfo, const std::string& stand) {
  try {
    return std::make_unique<daemon::PostgresRegistry>(conninfo, stand);
  } catch (const storage::StorageError& e) {
    throw std::runtime_error(std::string("the lab's registry (--to): ") + e.what());
  }
}

}  // namespace

int run_registry_init(const std::string& conninfo) {
  const auto lab = connect_lab(conninfo, "imucal");
  std::printf("the lab's registry is at schema version %d, this imucal's (created or migrated as needed)\n",
              lab->schema_version());
  return 0;
}

int run_registry_migrate(const RegistryMigrateArgs& a) {
  const fs::path data_dir(a.data_dir);
  const fs::path db_path = data_dir / "imucald.db";
  std::error_code ec;
  if (!fs::is_regular_file(db_path, ec))
    throw std::runtime_error("no imucald database in '" + a.data_dir + "' (expected " + db_path.string() + ")");
  const StandSettings settings = stand_settings(a);
  const DataDirLock lock(data_dir);
  daemon::DaemonDb db(db_path.string());
  daemon::StandRegistrySource source;
  source.db = &db;
  source.stand = settings.stand;
  source.label = a.data_dir;
  source.limits_json = read_limits(settings.limits);
  source.actor = login_name(a.operator_name);
  const auto lab = connect_lab(a.to, settings.stand);
  std::printf("%s stand '%s' from %s into the lab's registry (schema version %d)\n",
              a.dry_run ? "dry run, nothing is written: moving" : "moving", settings.stand.c_str(), a.data_dir.c_str(),
              lab->schema_version());
  daemon::MigrationReport report;
  try {
    report = daemon::migrate_stand_registry(source, *lab, a.dry_run);
  } catch (const storage::pg::PgError& e) {
    throw std::runtime_error(std::string("the lab's registry (--to): ") + e.what() + "; nothing was copied");
  }
  for (const std::string& line : report.lines()) std::printf("  %s\n", line.c_str());
  if (!source.limits_json) std::printf("  note: no limits file at %s: no limits to move\n", settings.limits.string().c_str());
  // A stand that ran on a lab's server already: what its journal holds is its imucald's to replay.
  if (fs::exists(data_dir / "registry-journal.jsonl", ec))
    std::printf("  note: %s holds registry-journal.jsonl: this stand wrote to a lab's registry already; the writes "
                "waiting there are replayed by its imucald, not by this command\n",
                a.data_dir.c_str());
  if (report.copied() == 0)
    std::printf("nothing to copy: the lab's registry holds all of it (%lld rows skipped)\n",
                static_cast<long long>(report.skipped()));
  else
    std::printf("%s: %lld rows %s, %lld skipped\n", a.dry_run ? "dry run" : "done", static_cast<long long>(report.copied()),
                a.dry_run ? "would be copied" : "copied", static_cast<long long>(report.skipped()));
  return 0;
}

}  // namespace imucal::cli
