// imucal import: an imucal-recording/1 bundle read into a run database (docs/storage.md), its gaps
// listed.
#include "cli/commands.hpp"

#include <cstdio>

#include "storage/bundle.hpp"

namespace imucal::cli {

int run_import(const std::string& dir, const std::string& db_path) {
  const storage::ImportReport r = storage::import_bundle(dir, db_path);
  std::printf("imported %lld frames, %lld temperature samples into %s\n", static_cast<long long>(r.frames),
              static_cast<long long>(r.temp_samples), db_path.c_str());
  for (const auto& g : r.gaps)
    std::printf("  gap: %.6f s .. %.6f s (frames.csv line %lld)\n", g.t0_s, g.t1_s, static_cast<long long>(g.line));
  return 0;
}

}  // namespace imucal::cli
