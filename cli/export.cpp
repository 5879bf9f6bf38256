// imucal export: a run database written as an imucal-recording/1 bundle (docs/storage.md).
#include "cli/commands.hpp"

#include <cstdio>

#include "storage/bundle.hpp"
#include "storage/run_db.hpp"

namespace imucal::cli {

int run_export(const std::string& db_path, const std::string& dir) {
  const auto db = storage::RunDb::open(db_path);
  storage::export_bundle(db, dir);
  std::printf("exported %lld frames to %s\n", static_cast<long long>(db.frame_count()), dir.c_str());
  return 0;
}

}  // namespace imucal::cli
