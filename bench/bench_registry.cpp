// bench_registry (issue 38): the lab's registry's operations per second, as a stand does them when
// a run ends: take a certificate number, insert the issued certificate, append an audit entry,
// record the unit's calibration. One stand on its own SQLite database (the daemon's, with the
// site's sequence file), then one and three stands at once (a connection and a thread each) on a
// private PostgreSQL server started as the tests start theirs (tests/postgres_server.hpp), but
// syncing its commits to the disk as a lab's server does. Prints one JSON line (bench/README.md).
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <memory>
#include <stdexcept>
#include <string>
#include <thread>
#include <vector>

#include <unistd.h>

#include <CLI/CLI.hpp>
#include <nlohmann/json.hpp>

#include "daemon/db/audit_chain.hpp"
#include "daemon/db/daemon_db.hpp"
#include "daemon/registry/calibrations.hpp"
#include "daemon/registry/certificate_sequence.hpp"
#include "daemon/registry/postgres_registry.hpp"
#include "daemon/registry/sqlite_registry.hpp"
#include "tests/postgres_server.hpp"

using namespace imucal::daemon;
using Clock = std::chrono::steady_clock;
namespace fs = std::filesystem;

namespace {

constexpr std::int64_t kCampaigns = 50;  // each stand's campaigns, their certificates in turn

// What one stand's thread did: each operation's wall time.
struct StandRun {
  std::vector<double> op_ms;
};

// A unit's campaign row as a stand records it at a run's end (the model is a few kB of JSON).
CampaignRow campaign_row(std::int64_t id) {
  CampaignRow row;
  row.id = id;
  row.name = "bench " + std::to_string(id);
  row.spec_json = R"({"program":"direct"})";
  row.program_label = "direct";
  row.duration_s = 3600.0;
  row.state = RunState::Done;
  row.created_ms = 1700000000000 + id;
  row.model_json = std::string(R"({"format":"imucal-imu-model/1","pad":")") + std::string(3000, 'm') + "\"}";
  row.imu_serial = "FOG-" + std::to_string(id % 10);
  row.imu_part_number = "PN-100";
  row.complete = true;
  return row;
}

// The four writes of one issue; `i` numbers the stand's operations.
void one_issue(Registry& registry, std::int64_t i, const std::string& content) {
  const std::int64_t campaign = 1 + i % kCampaigns;
  IssuedCertificateRow row;
  row.sequence = registry.next_certificate_sequence();
  row.number = "BENCH-2026-" + std::to_string(row.sequence);
  row.campaign_id = campaign;
  row.issued_ms = now_unix_ms();
  row.content_json = content;
  row.content_sha256 = "0123456789abcdef0123456789abcdef0123456789abcdef0123456789abcdef";
  row.reason = "the run ended";
  registry.insert_issued(row);
  registry.append_audit("imucald", "certificate.issued", row.number,
                        R"({"campaign":)" + std::to_string(campaign) + R"(,"reason":"the run ended"})", std::nullopt);
  registry.record_calibration(campaign_row(campaign));
}

StandRun run_for(Registry& registry, double seconds) {
  const std::string content = R"({"format":"imucal-certificate/1","pad":")" + std::string(6000, 'c') + "\"}";
  StandRun out;
  const auto end = Clock::now() + std::chrono::duration<double>(seconds);
  for (std::int64_t i = 0; Clock::now() < end; ++i) {
    const auto t0 = Clock::now();
    one_issue(registry, i, content);
    out.op_ms.push_back(std::chrono::duration<double, std::milli>(Clock::now() - t0).count());
  }
  return out;
}

double percentile(std::vector<double> v, double p) {
  if (v.empty()) return 0.0;
  std::sort(v.begin(), v.end());
  return v[std::min(v.size() - 1, static_cast<std::size_t>(p * static_cast<double>(v.size())))];
}

nlohmann::json figures(const std::vector<StandRun>& stands, double seconds) {
  std::vector<double> all;
  nlohmann::json per_stand = nlohmann::json::array();
  for (const StandRun& s : stands) {
    all.insert(all.end(), s.op_ms.begin(), s.op_ms.end());
    per_stand.push_back(static_cast<double>(s.op_ms.size()) / seconds);
  }
  return {{"stands", stands.size()},
          {"ops", all.size()},
          {"ops_per_s", static_cast<double>(all.size()) / seconds},
          {"per_stand_ops_per_s", per_stand},
          {"p50_ms", percentile(all, 0.5)},
          {"p99_ms", percentile(all, 0.99)}};
}

// One stand on the daemon's own database, numbered from the site's sequence file (flock, fsync,
// rename: what a stand without a lab server pays per number).
nlohmann::json bench_sqlite(const std::string& dir, double seconds) {
  fs::create_directories(dir);
  DaemonDb db(dir + "/imucald.db");
  for (std::int64_t i = 1; i <= kCampaigns; ++i)
    db.insert_campaign("bench " + std::to_string(i), "{}", "direct", 3600.0, "bench", CampaignUnit{"FOG-1", "PN-100"});
  CertificateSequence sequence(dir + "/sequence.json");
  SqliteRegistry registry(db, sequence, "stand-1", dir + "/limits.json");
  nlohmann::json out = figures({run_for(registry, seconds)}, seconds);
  out["chain_intact"] = check_audit_chain(db.audit_chain()).ok();
  return out;
}

// `stands` stands at once, each its own connection and thread, on a fresh database.
nlohmann::json bench_postgres(imucaltest::PostgresServer& server, int stands, double seconds) {
  const std::string conninfo = server.create_database(imucaltest::PostgresServer::unique_name("bench"));
  std::vector<std::unique_ptr<PostgresRegistry>> registries;
  for (int s = 1; s <= stands; ++s)
    registries.push_back(std::make_unique<PostgresRegistry>(conninfo, "stand-" + std::to_string(s)));
  std::vector<StandRun> runs(static_cast<std::size_t>(stands));
  std::vector<std::string> errors(runs.size());
  std::vector<std::thread> threads;
  for (std::size_t s = 0; s < registries.size(); ++s)
    threads.emplace_back([&, s] {
      try {
        runs[s] = run_for(*registries[s], seconds);
      } catch (const std::exception& e) {
        errors[s] = e.what();
      }
    });
  for (std::thread& t : threads) t.join();
  for (const std::string& e : errors)
    if (!e.empty()) throw std::runtime_error("a stand's registry failed: " + e);
  nlohmann::json out = figures(runs, seconds);
  // What the contention must not break: one chain, no number twice.
  PostgresRegistry check(conninfo, "check");
  out["chain_intact"] = check_audit_chain(check.audit_chain()).ok();
  out["numbers_distinct"] = check.max_certificate_sequence() == static_cast<std::int64_t>(out["ops"].get<std::size_t>());
  return out;
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"bench_registry: the lab's registry's operations per second (issue 38, bench/README.md)"};
  double seconds = 10.0;
  int stands = 3;
  bool durable = true;
  app.add_option("--seconds", seconds, "each configuration's run, s")->capture_default_str()->check(CLI::PositiveNumber);
  app.add_option("--stands", stands, "stands at once on PostgreSQL")->capture_default_str()->check(CLI::Range(1, 32));
  app.add_option("--durable", durable, "the PostgreSQL server syncs its commits (fsync on), as a lab's does")
      ->capture_default_str();
  CLI11_PARSE(app, argc, argv);

  const std::string dir = (fs::temp_directory_path() / ("imucal-bench-registry-" + std::to_string(getpid()))).string();
  nlohmann::json out = {{"bench", "registry"}, {"seconds", seconds}};
  try {
    out["sqlite_1_stand"] = bench_sqlite(dir + "/sqlite", seconds);
    imucaltest::PostgresServer server(durable);
    if (!server.running()) {
      std::fprintf(stderr, "bench_registry: no PostgreSQL server: %s\n",
                   server.skip_reason().empty() ? server.error().c_str() : server.skip_reason().c_str());
      return 1;
    }
    out["postgresql_fsync"] = durable;
    out["postgresql_1_stand"] = bench_postgres(server, 1, seconds);
    out["postgresql_" + std::to_string(stands) + "_stands"] = bench_postgres(server, stands, seconds);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "bench_registry: %s\n", e.what());
    fs::remove_all(dir);
    return 1;
  }
  fs::remove_all(dir);
  std::printf("%s\n", out.dump().c_str());
  return 0;
}
