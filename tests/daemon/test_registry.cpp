// The lab's registry (daemon/registry/registry.hpp, issue 38): one suite, run against both
// implementations: the daemon's SQLite database (with the site's sequence file) and a PostgreSQL
// server (a private one, tests/postgres_server.hpp; skipped, saying what is missing, without it).
#include <gtest/gtest.h>

#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <filesystem>
#include <fstream>
#include <memory>
#include <mutex>
#include <set>
#include <string>
#include <thread>
#include <vector>

#include "daemon/db/daemon_db.hpp"
#include "daemon/production/certificates.hpp"
#include "daemon/registry/certificate_sequence.hpp"
#include "daemon/production/limits_file.hpp"
#include "daemon/production/unit_registry.hpp"
#include "daemon/registry/calibrations.hpp"
#include "daemon/registry/journaled_registry.hpp"
#include "daemon/registry/postgres_registry.hpp"
#include "daemon/registry/sqlite_registry.hpp"
#include "tests/daemon/certificate_rows.hpp"
#include "tests/postgres_server.hpp"
#include "tests/test_paths.hpp"

using namespace imucal::daemon;

namespace {

constexpr std::size_t kCampaigns = 5;  // campaigns 1..5 exist in every store

// The daemon's database in a fresh directory; each connect() is another connection to it (another
// DaemonDb on the same file, as another process would open it) with the same sequence file.
class SqliteStore {
 public:
  std::string open() {
    static int n = 0;
    dir_ = imucaltest::test_tmp_dir() + "/registry-" + std::to_string(getpid()) + "-" + std::to_string(++n);
    std::filesystem::remove_all(dir_);
    std::filesystem::create_directories(dir_);
    DaemonDb db(dir_ + "/imucald.db");
    for (std::size_t i = 1; i <= kCampaigns; ++i) db.insert_campaign("c" + std::to_string(i), "{}", "test", 1.0, "test");
    return "";
  }
  ~SqliteStore() {
    dbs_.clear();
    sequences_.clear();
    std::error_code ignored;
    if (!dir_.empty()) std::filesystem::remove_all(dir_, ignored);
  }
  // The databases and the sequence live as long as the store (the registries refer to them).
  std::unique_ptr<Registry> connect() {
    std::lock_guard lock(mutex_);
    dbs_.push_back(std::make_unique<DaemonDb>(dir_ + "/imucald.db"));
    sequences_.push_back(std::make_unique<CertificateSequence>(dir_ + "/sequence"));
    return std::make_unique<SqliteRegistry>(*dbs_.back(), *sequences_.back(), "stand-a", dir_ + "/limits.json");
  }
  // The stand's own database, whose campaigns the registry records.
  DaemonDb& stand_db() {
    std::lock_guard lock(mutex_);
    if (!own_) own_ = std::make_unique<DaemonDb>(dir_ + "/imucald.db");
    return *own_;
  }

 private:
  std::string dir_;
  std::mutex mutex_;
  std::vector<std::unique_ptr<DaemonDb>> dbs_;
  std::vector<std::unique_ptr<CertificateSequence>> sequences_;
  std::unique_ptr<DaemonDb> own_;
};

// A fresh database on the private server; each connect() is another connection (another stand's
// imucald would hold one).
class PostgresStore {
 public:
  std::string open() {
    auto& server = imucaltest::shared_postgres_server();
    if (!server.skip_reason().empty()) return "skip: " + server.skip_reason();
    if (!server.running()) return server.error();
    conninfo_ = server.create_database(imucaltest::PostgresServer::unique_name("registry"));
    return "";
  }
  std::unique_ptr<Registry> connect() { return std::make_unique<PostgresRegistry>(conninfo_, "stand-a"); }
  const std::string& conninfo() const { return conninfo_; }
  // The stand's own database (a fresh one), whose campaigns the registry records.
  DaemonDb& stand_db() {
    if (!own_) {
      dir_ = imucaltest::test_tmp_dir() + "/registry-stand-" + std::to_string(getpid()) + "-" +
             imucaltest::PostgresServer::unique_name("s");
      std::filesystem::remove_all(dir_);
      std::filesystem::create_directories(dir_);
      own_ = std::make_unique<DaemonDb>(dir_ + "/imucald.db");
    }
    return *own_;
  }
  ~PostgresStore() {
    own_.reset();
    std::error_code ignored;
    if (!dir_.empty()) std::filesystem::remove_all(dir_, ignored);
  }

 private:
  std::string conninfo_;
  std::string dir_;
  std::unique_ptr<DaemonDb> own_;
};

template <class Store>
class RegistryTest : public ::testing::Test {
 protected:
  void SetUp() override {
    const std::string problem = store_.open();
    if (problem.rfind("skip: ", 0) == 0) GTEST_SKIP() << problem.substr(6);
    ASSERT_EQ(problem, "");
    registry_ = store_.connect();
  }
  Store store_;
  std::unique_ptr<Registry> registry_;
};

class StoreNames {
 public:
  template <class T>
  static std::string GetName(int) {
    return std::is_same_v<T, SqliteStore> ? "Sqlite" : "Postgres";
  }
};
using Stores = ::testing::Types<SqliteStore, PostgresStore>;
TYPED_TEST_SUITE(RegistryTest, Stores, StoreNames);

using imucaltest::certificate_row;

TYPED_TEST(RegistryTest, CertificateNumbersFollowOneAnotherAndTheHighestIsKnown) {
  auto& reg = *this->registry_;
  EXPECT_EQ(reg.max_certificate_sequence(), 0);
  const std::int64_t a = reg.next_certificate_sequence();
  const std::int64_t b = reg.next_certificate_sequence();
  EXPECT_EQ(a, 1);
  EXPECT_EQ(b, 2);
  reg.insert_issued(certificate_row(b, 1));
  EXPECT_EQ(reg.max_certificate_sequence(), 2);
  reg.insert_certificate({2, "LAB-2025-000007", 7, 1600000000000, R"({"devices":"sim"})"});
  EXPECT_EQ(reg.max_certificate_sequence(), 7);
  const auto legacy = reg.certificate(2);
  ASSERT_TRUE(legacy);
  EXPECT_EQ(legacy->number, "LAB-2025-000007");
  EXPECT_EQ(legacy->bench_json, R"({"devices":"sim"})");
  EXPECT_FALSE(reg.certificate(3));
}

TYPED_TEST(RegistryTest, ALaterCertificateSupersedesTheOneInForceOnce) {
  auto& reg = *this->registry_;
  const auto first = certificate_row(1, 1);
  reg.insert_issued(first);
  EXPECT_EQ(reg.current_issued(1).value_or(IssuedCertificateRow{}).number, first.number);
  const auto second = certificate_row(2, 1, first.number);
  reg.insert_issued(second);
  EXPECT_EQ(reg.current_issued(1).value_or(IssuedCertificateRow{}).number, second.number);
  const auto history = reg.issued_history(1);
  ASSERT_EQ(history.size(), 2U);
  EXPECT_EQ(history[0].superseded_by, second.number);
  EXPECT_EQ(history[1].supersedes, first.number);
  EXPECT_EQ(history[1].content_json, second.content_json);
  EXPECT_EQ(history[1].signed_json, std::nullopt);
  EXPECT_EQ(reg.campaigns_with_issued(), std::vector<std::int64_t>{1});
  EXPECT_FALSE(reg.issued("LAB-2026-999999"));
  EXPECT_FALSE(reg.current_issued(2));
  // Superseded once: a third one naming the first again is refused, and nothing of it is kept.
  EXPECT_THROW(reg.insert_issued(certificate_row(3, 1, first.number)), imucal::storage::StorageError);
  EXPECT_FALSE(reg.issued(certificate_row(3, 1).number));
  // A number is never issued twice.
  EXPECT_THROW(reg.insert_issued(certificate_row(2, 2)), imucal::storage::StorageError);
}

TYPED_TEST(RegistryTest, APrintedPageIsStoredOnceAndKept) {
  auto& reg = *this->registry_;
  const auto c = certificate_row(1, 1);
  reg.insert_issued(c);
  EXPECT_TRUE(reg.insert_issued_page({c.number, "<html>1</html>", "h1", 5, "ada"}));
  EXPECT_FALSE(reg.insert_issued_page({c.number, "<html>2</html>", "h2", 6, "bob"}));
  const auto with = reg.issued_page(c.number, true);
  ASSERT_TRUE(with);
  EXPECT_EQ(with->html, "<html>1</html>");
  EXPECT_EQ(with->stored_by, "ada");
  const auto without = reg.issued_page(c.number, false);
  ASSERT_TRUE(without);
  EXPECT_EQ(without->html, "");
  EXPECT_EQ(without->sha256, "h1");
  EXPECT_FALSE(reg.issued_page("LAB-2026-999999", true));
}

TYPED_TEST(RegistryTest, AnOverdueOverrideIsKeptWithItsCampaignUntilRemoved) {
  auto& reg = *this->registry_;
  EXPECT_FALSE(reg.overdue_override(3));
  reg.insert_overdue_override({3, 42, "ada", "customer waits", R"([{"instrument":"table"}])", "the rate table ..."});
  const auto o = reg.overdue_override(3);
  ASSERT_TRUE(o);
  EXPECT_EQ(o->by, "ada");
  EXPECT_EQ(o->t_ms, 42);
  EXPECT_EQ(o->instruments_json, R"([{"instrument":"table"}])");
  EXPECT_THROW(reg.insert_overdue_override({3, 43, "bob", "again", "[]", ""}), imucal::storage::StorageError);
  reg.remove_overdue_override(3);
  EXPECT_FALSE(reg.overdue_override(3));
}

TYPED_TEST(RegistryTest, TheAuditTrailIsAChainAndAnsweredByQuery) {
  auto& reg = *this->registry_;
  EXPECT_FALSE(reg.audit_chain().head);
  reg.append_audit("ada", "campaign.created", "campaign 1", R"({"name":"c1"})", 1000);
  reg.append_audit("bob", "limits.replaced", "limits", R"({})", 2000);
  const AuditEntry last = reg.append_audit("ada", "campaign.command", "campaign 1", R"({"command":"start"})", 3000);
  EXPECT_EQ(last.seq, 3);
  const AuditChain chain = reg.audit_chain();
  const auto& trail = chain.entries;
  ASSERT_EQ(trail.size(), 3U);
  EXPECT_EQ(trail[0].prev_sha256, kAuditGenesis);
  EXPECT_EQ(trail[2].sha256, last.sha256);
  ASSERT_TRUE(chain.head);
  EXPECT_EQ(chain.head->first, 3);
  EXPECT_EQ(chain.head->second, last.sha256);
  EXPECT_TRUE(check_audit_chain(chain).ok());

  Registry::AuditQuery q;
  q.actor = "ada";
  auto found = reg.audit_entries(q);
  ASSERT_EQ(found.size(), 2U);
  EXPECT_EQ(found[0].seq, 3);  // newest first
  q = {};
  q.action_prefix = "campaign.";
  q.from_ms = 2000;
  found = reg.audit_entries(q);
  ASSERT_EQ(found.size(), 1U);
  EXPECT_EQ(found[0].action, "campaign.command");
  q = {};
  q.subject = "limits";
  EXPECT_EQ(reg.audit_entries(q).size(), 1U);
  q = {};
  q.limit = 2;
  q.to_ms = 3000;
  EXPECT_EQ(reg.audit_entries(q).size(), 2U);
}

// A campaign of the stand's own database that names `serial` and ended done with `model_json`,
// having run its whole program (`complete`) or stopped early with results, as a run leaves it.
std::int64_t unit_run(DaemonDb& db, const std::string& serial, bool complete, const std::string& model_json) {
  const std::int64_t id = db.insert_campaign("run of " + serial, "{}", "test", 10.0, "created", CampaignUnit{serial, "FOG-3A"});
  EXPECT_TRUE(db.set_state(id, RunState::Queued, "queued"));
  EXPECT_TRUE(db.set_state(id, RunState::Running, "started"));
  db.set_model(id, model_json);
  db.set_complete(id, complete);
  EXPECT_TRUE(db.set_state(id, RunState::Done, "ended"));
  return id;
}

TYPED_TEST(RegistryTest, AUnitsCalibrationsAreReadOldestFirstEachNamingItsStand) {
  auto& reg = *this->registry_;
  DaemonDb& db = this->store_.stand_db();
  EXPECT_TRUE(reg.unit_campaigns(std::nullopt).empty());
  const std::int64_t a = unit_run(db, "FOG-7", true, R"({"k":1})");
  const std::int64_t b = unit_run(db, "FOG-8", true, R"({"k":2})");
  const std::int64_t c = unit_run(db, "FOG-7", false, R"({"k":3})");
  for (const std::int64_t id : {a, b, c}) EXPECT_TRUE(record_unit_calibration(db, reg, id));
  const std::int64_t no_unit = db.insert_campaign("no unit", "{}", "test", 1.0, "created");
  EXPECT_FALSE(record_unit_calibration(db, reg, no_unit));  // nothing recorded

  auto fog7 = reg.unit_campaigns("FOG-7");
  ASSERT_EQ(fog7.size(), 2U);
  EXPECT_EQ(fog7[0].id, a);
  EXPECT_EQ(fog7[1].id, c);
  EXPECT_EQ(fog7[0].stand, "stand-a");
  EXPECT_EQ(fog7[1].stand, "stand-a");
  EXPECT_EQ(fog7[0].complete, std::optional<bool>(true));
  EXPECT_EQ(fog7[1].state, RunState::Done);
  EXPECT_EQ(fog7[1].complete, std::optional<bool>(false));
  EXPECT_FALSE(counts_as_calibration(fog7[1]));  // partial: not a calibration until accepted
  EXPECT_EQ(fog7[1].model_json, std::optional<std::string>(R"({"k":3})"));
  EXPECT_EQ(fog7[1].imu_part_number, std::optional<std::string>("FOG-3A"));
  EXPECT_TRUE(fog7[1].ended_ms.has_value());
  EXPECT_FALSE(fog7[1].accepted_reason);
  const auto all = reg.unit_campaigns(std::nullopt);
  ASSERT_EQ(all.size(), 3U);
  EXPECT_EQ(all[1].id, b);
  EXPECT_TRUE(reg.unit_campaigns("FOG-9").empty());

  // An operator's acceptance recorded again replaces the row: still two calibrations of FOG-7.
  db.accept(c, "enough positions", "ada");
  EXPECT_TRUE(record_unit_calibration(db, reg, c));
  fog7 = reg.unit_campaigns("FOG-7");
  ASSERT_EQ(fog7.size(), 2U);
  EXPECT_EQ(fog7[1].accepted_reason, std::optional<std::string>("enough positions"));
  EXPECT_EQ(fog7[1].accepted_by, std::optional<std::string>("ada"));
  EXPECT_TRUE(counts_as_calibration(fog7[1]));
}

// The limits are one document of the store: the last put, read by every connection.
TYPED_TEST(RegistryTest, TheLimitsAreTheLastDocumentPut) {
  auto& reg = *this->registry_;
  EXPECT_FALSE(reg.limits_document());
  const std::string first = R"({"format": "imucal-limits/1", "parts": {}})";
  const std::string second = R"({"format": "imucal-limits/1", "parts": {"FOG-3A": {}}})";
  reg.put_limits_document(first, "ada");
  EXPECT_EQ(reg.limits_document(), std::optional<std::string>(first));
  reg.put_limits_document(second, "bob");
  EXPECT_EQ(reg.limits_document(), std::optional<std::string>(second));
  EXPECT_EQ(this->store_.connect()->limits_document(), std::optional<std::string>(second));
}

// The limits are read from the store at each asking: one put through another connection (another
// stand) judges at once; a document this imucald cannot read stops a start, naming it, and later
// keeps the limits last read.
TYPED_TEST(RegistryTest, LimitsAreReadAgainAndAMisreadDocumentKeepsTheLastOnes) {
  LimitsFile here(*this->registry_, "limits.json");
  EXPECT_TRUE(here.current().parts.empty());
  const auto other = this->store_.connect();
  LimitsFile elsewhere(*other, "limits.json");
  here.replace({{"format", "imucal-limits/1"}, {"part_numbers", {{"FOG-3A", {{"gyro.bias_dph", {{"max_abs", 1.0}}}}}}}},
               "ada");
  EXPECT_EQ(elsewhere.current().parts.size(), 1U);
  this->registry_->put_limits_document("{not json", "a hand edit");
  EXPECT_EQ(elsewhere.current().parts.size(), 1U);
  EXPECT_EQ(elsewhere.current().source, "limits.json");
  try {
    LimitsFile at_start(*other, "limits.json");
    ADD_FAILURE() << "limits misread at a start were accepted";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("acceptance limits limits.json: not valid JSON"), std::string::npos) << e.what();
  }
}

// Issue 38's acceptance: three stands (connections) issuing 20 certificates each at the same time
// get 60 distinct numbers, each stand's in the order it issued them, none lost.
TYPED_TEST(RegistryTest, ThreeConnectionsIssuingAtOnceNeverShareANumber) {
  constexpr std::size_t kConnections = 3;
  constexpr std::size_t kEach = 20;
  std::vector<std::unique_ptr<Registry>> connections;
  for (std::size_t i = 0; i < kConnections; ++i) connections.push_back(this->store_.connect());
  std::vector<std::vector<std::int64_t>> taken(kConnections);
  std::vector<std::string> errors(kConnections);
  std::vector<std::thread> threads;
  for (std::size_t i = 0; i < kConnections; ++i) {
    threads.emplace_back([&, i] {
      try {
        for (std::size_t k = 0; k < kEach; ++k) {
          const std::int64_t sequence = connections[i]->next_certificate_sequence();
          connections[i]->insert_issued(certificate_row(sequence, 1 + static_cast<std::int64_t>(k % kCampaigns)));
          taken[i].push_back(sequence);
        }
      } catch (const std::exception& e) {
        errors[i] = e.what();
      }
    });
  }
  for (auto& t : threads) t.join();
  std::set<std::int64_t> all;
  for (std::size_t i = 0; i < kConnections; ++i) {
    EXPECT_EQ(errors[i], "");
    EXPECT_TRUE(std::is_sorted(taken[i].begin(), taken[i].end())) << "connection " << i;
    all.insert(taken[i].begin(), taken[i].end());
  }
  ASSERT_EQ(all.size(), kConnections * kEach);
  EXPECT_EQ(*all.begin(), 1);
  EXPECT_EQ(*all.rbegin(), static_cast<std::int64_t>(kConnections * kEach));
  for (const std::int64_t s : all) EXPECT_TRUE(this->registry_->issued(certificate_row(s, 1).number)) << s;
  EXPECT_EQ(this->registry_->max_certificate_sequence(), static_cast<std::int64_t>(kConnections * kEach));
}

// One chain for every writer: three connections appending at once leave a trail without gaps.
TYPED_TEST(RegistryTest, ThreeConnectionsAppendingAuditEntriesAtOnceKeepOneChain) {
  constexpr std::size_t kConnections = 3;
  std::vector<std::unique_ptr<Registry>> connections;
  for (std::size_t i = 0; i < kConnections; ++i) connections.push_back(this->store_.connect());
  std::vector<std::thread> threads;
  std::vector<std::string> errors(kConnections);
  for (std::size_t i = 0; i < kConnections; ++i) {
    threads.emplace_back([&, i] {
      try {
        for (int k = 0; k < 10; ++k)
          connections[i]->append_audit("stand" + std::to_string(i), "test.append", "s", "{}", std::nullopt);
      } catch (const std::exception& e) {
        errors[i] = e.what();
      }
    });
  }
  for (auto& t : threads) t.join();
  for (const auto& e : errors) EXPECT_EQ(e, "");
  const AuditChain chain = this->registry_->audit_chain();
  EXPECT_EQ(chain.entries.size(), 30U);
  const AuditCheck check = check_audit_chain(chain);
  EXPECT_TRUE(check.ok()) << check.message;
}

// A reader beside a writer: each read of the trail and its head is one snapshot, never a trail
// that stops short of the head just recorded (which reads as entries deleted: the false alarm a
// GET /api/audit raised while a campaign's start was being journaled).
TYPED_TEST(RegistryTest, TheChainReadWhileAnotherConnectionAppendsAlwaysHolds) {
  const std::unique_ptr<Registry> writer = this->store_.connect();
  std::atomic<bool> done{false};
  std::string writer_error;
  std::thread appending([&] {
    try {
      for (int k = 0; k < 60; ++k) writer->append_audit("writer", "test.append", "s", "{}", std::nullopt);
    } catch (const std::exception& e) {
      writer_error = e.what();
    }
    done = true;
  });
  int reads = 0;
  std::vector<std::string> broken;
  while (!done || reads == 0) {
    const AuditCheck check = check_audit_chain(this->registry_->audit_chain());
    if (!check.ok()) broken.push_back(check.message);
    ++reads;
  }
  appending.join();
  EXPECT_EQ(writer_error, "");
  EXPECT_TRUE(broken.empty()) << broken.size() << " of " << reads << " reads broken, first: " << broken.front();
  EXPECT_EQ(this->registry_->audit_trail().size(), 60U);
}

// ---- Stands (issue 38, the lab overview) ----

StandRow stand(const std::string& name, std::int64_t t_ms) {
  return StandRow{name, "sim", "http://" + name + ":8080", "1.2.3", 5000, t_ms, t_ms, R"({"run":null})"};
}

TYPED_TEST(RegistryTest, AStandRegistersAndItsHeartbeatReplacesItsState) {
  auto& reg = *this->registry_;
  EXPECT_TRUE(reg.stands().empty());
  EXPECT_FALSE(reg.report_stand_state("stand-a", "{}", 1000));  // not registered yet: the caller registers
  reg.register_stand(stand("stand-a", 1000));
  ASSERT_EQ(reg.stands().size(), 1U);
  EXPECT_TRUE(reg.report_stand_state("stand-a", R"({"run":{"id":3}})", 6000));
  EXPECT_TRUE(reg.report_stand_state("stand-a", R"({"run":{"id":4}})", 11000));
  const auto stands = reg.stands();
  ASSERT_EQ(stands.size(), 1U);
  const StandRow& s = stands[0];
  EXPECT_EQ(s.name, "stand-a");
  EXPECT_EQ(s.bench, "sim");
  EXPECT_EQ(s.url, "http://stand-a:8080");
  EXPECT_EQ(s.version, "1.2.3");
  EXPECT_EQ(s.heartbeat_ms, 5000);
  EXPECT_EQ(s.registered_ms, 1000);
  EXPECT_EQ(s.last_seen_ms, 11000);
  EXPECT_EQ(s.state_json, R"({"run":{"id":4}})");  // only the latest

  // Started again (a new version, another address): one row, registered anew.
  StandRow again = stand("stand-a", 20000);
  again.version = "1.2.4";
  reg.register_stand(again);
  const auto after = reg.stands();
  ASSERT_EQ(after.size(), 1U);
  EXPECT_EQ(after[0].version, "1.2.4");
  EXPECT_EQ(after[0].registered_ms, 20000);
  EXPECT_EQ(after[0].state_json, R"({"run":null})");
}

// A lab: every stand's row, by name, each with its own state (PostgreSQL; the SQLite registry
// knows its own stand only, and a stand renamed replaces it).
TYPED_TEST(RegistryTest, StandsAreListedByName) {
  auto& reg = *this->registry_;
  reg.register_stand(stand("stand-b", 1000));
  reg.register_stand(stand("stand-a", 2000));
  auto other = this->store_.connect();  // another stand's connection
  EXPECT_TRUE(other->report_stand_state("stand-a", R"({"queue":2})", 3000));
  const auto stands = reg.stands();
  if constexpr (std::is_same_v<TypeParam, SqliteStore>) {
    ASSERT_EQ(stands.size(), 1U);
    EXPECT_EQ(stands[0].name, "stand-a");
    EXPECT_FALSE(reg.report_stand_state("stand-b", "{}", 4000));
  } else {
    ASSERT_EQ(stands.size(), 2U);
    EXPECT_EQ(stands[0].name, "stand-a");
    EXPECT_EQ(stands[0].state_json, R"({"queue":2})");
    EXPECT_EQ(stands[1].name, "stand-b");
    EXPECT_EQ(stands[1].last_seen_ms, 1000);
    EXPECT_TRUE(reg.report_stand_state("stand-b", "{}", 4000));
  }
}

// The lab's accounts: put (replacing one of the same name), listed by name, removed once; another
// stand's connection sees them (on SQLite the stand's own database is the only one).
TYPED_TEST(RegistryTest, AccountsArePutReplacedListedAndRemoved) {
  auto& reg = *this->registry_;
  EXPECT_TRUE(reg.users().empty());
  reg.put_user({"grace", "viewer", "$argon2id$hash-1", 1000, "ada"});
  reg.put_user({"alan", "operator", "$argon2id$hash-2", 2000, "ada"});
  reg.put_user({"grace", "operator", "$argon2id$hash-3", 3000, "alan"});  // replaced
  auto other = this->store_.connect();
  const auto users = other->users();
  ASSERT_EQ(users.size(), 2U);
  EXPECT_EQ(users[0].name, "alan");
  EXPECT_EQ(users[1].name, "grace");
  EXPECT_EQ(users[1].role, "operator");
  EXPECT_EQ(users[1].password_hash, "$argon2id$hash-3");
  EXPECT_EQ(users[1].changed_ms, 3000);
  EXPECT_EQ(users[1].changed_by, "alan");
  EXPECT_TRUE(reg.remove_user("grace"));
  EXPECT_FALSE(reg.remove_user("grace"));
  ASSERT_EQ(reg.users().size(), 1U);
  EXPECT_ANY_THROW(reg.put_user({"eve", "admin", "$argon2id$h", 4000, "ada"}));  // no such role
}

// PostgreSQL's own: the schema is versioned and migrated once; a newer one is refused.
class PostgresRegistrySchema : public ::testing::Test {
 protected:
  void SetUp() override {
    const std::string problem = store_.open();
    if (problem.rfind("skip: ", 0) == 0) GTEST_SKIP() << problem.substr(6);
    ASSERT_EQ(problem, "");
  }
  PostgresStore store_;
};

TEST_F(PostgresRegistrySchema, IsMigratedOnceAndANewerOneIsRefused) {
  {
    PostgresRegistry first(store_.conninfo(), "stand-a");
    EXPECT_EQ(first.schema_version(), PostgresRegistry::kSchemaVersion);
    first.append_audit("ada", "a", "s", "{}", 1);
  }
  {
    PostgresRegistry again(store_.conninfo(), "stand-b");  // nothing migrated twice, nothing lost
    EXPECT_EQ(again.schema_version(), PostgresRegistry::kSchemaVersion);
    EXPECT_EQ(again.audit_trail().size(), 1U);
  }
  {
    imucal::storage::pg::Connection raw(store_.conninfo(), "test");
    raw.exec("UPDATE registry_schema SET version = $1", {99});
  }
  try {
    PostgresRegistry newer(store_.conninfo(), "stand-a");
    FAIL() << "a newer schema was accepted";
  } catch (const DbError& e) {
    EXPECT_NE(std::string(e.what()).find("schema version 99"), std::string::npos) << e.what();
  }
}

// The certificates a stand sees are its own campaigns' (campaign ids are numbered per stand).
TEST_F(PostgresRegistrySchema, EachStandSeesItsOwnCampaigns) {
  PostgresRegistry a(store_.conninfo(), "stand-a");
  PostgresRegistry b(store_.conninfo(), "stand-b");
  a.insert_issued(certificate_row(a.next_certificate_sequence(), 1));
  b.insert_issued(certificate_row(b.next_certificate_sequence(), 1));
  EXPECT_EQ(a.current_issued(1).value_or(IssuedCertificateRow{}).sequence, 1);
  EXPECT_EQ(b.current_issued(1).value_or(IssuedCertificateRow{}).sequence, 2);
  EXPECT_EQ(a.issued_history(1).size(), 1U);
  EXPECT_TRUE(a.issued(certificate_row(2, 1).number));  // a number is the lab's: found from any stand
}

// A registry of version 2 (before the units' calibrations and the limits, the stands and the
// accounts) is migrated to the current version by the next imucald that connects, keeping what it
// held.
TEST_F(PostgresRegistrySchema, AVersion2RegistryGainsTheCalibrationsAndTheLimits) {
  {
    PostgresRegistry first(store_.conninfo(), "stand-a");
    first.append_audit("ada", "a", "s", "{}", 1);
  }
  {
    imucal::storage::pg::Connection raw(store_.conninfo(), "test");
    raw.exec_script("DROP TABLE calibration; DROP TABLE limits; DROP TABLE stand; DROP TABLE lab_user; UPDATE registry_schema SET version = 2;");
  }
  PostgresRegistry again(store_.conninfo(), "stand-a");
  EXPECT_EQ(again.schema_version(), PostgresRegistry::kSchemaVersion);
  EXPECT_TRUE(again.stands().empty());
  EXPECT_EQ(again.audit_trail().size(), 1U);
  EXPECT_TRUE(again.unit_campaigns(std::nullopt).empty());
  EXPECT_FALSE(again.limits_document());
}

// A row of a campaign `id` of a stand that names `serial`, ended done with a model.
CampaignRow calibration_row(std::int64_t id, const std::string& serial, std::int64_t created_ms, const std::string& model) {
  CampaignRow r;
  r.id = id;
  r.name = "run " + std::to_string(id);
  r.spec_json = "{}";
  r.program_label = "direct";
  r.duration_s = 10.0;
  r.state = RunState::Done;
  r.created_ms = created_ms;
  r.ended_ms = created_ms + 10000;
  r.program_time_s = 10.0;
  r.model_json = model;
  r.imu_serial = serial;
  r.imu_part_number = "FOG-3A";
  r.complete = true;
  return r;
}

// Issue 38: a unit calibrated on two stands has one history, each calibration naming its stand
// (both stands' campaign 1); limits put through one stand judge the other's next run.
TEST_F(PostgresRegistrySchema, TwoStandsShareAUnitsHistoryAndTheLimits) {
  PostgresRegistry a(store_.conninfo(), "stand-a");
  PostgresRegistry b(store_.conninfo(), "stand-b");
  LimitsFile limits_b(b, "the lab's registry");
  EXPECT_TRUE(limits_b.current().parts.empty());

  a.record_calibration(calibration_row(1, "FOG-7", 1000, R"({"k":1})"));
  b.record_calibration(calibration_row(1, "FOG-7", 2000, R"({"k":2})"));
  b.record_calibration(calibration_row(2, "FOG-8", 3000, R"({"k":3})"));
  for (Registry* stand : {static_cast<Registry*>(&a), static_cast<Registry*>(&b)}) {
    const auto history = stand->unit_campaigns("FOG-7");
    ASSERT_EQ(history.size(), 2U);
    EXPECT_EQ(history[0].stand, "stand-a");
    EXPECT_EQ(history[0].model_json, std::optional<std::string>(R"({"k":1})"));
    EXPECT_EQ(history[1].stand, "stand-b");
    EXPECT_EQ(history[1].model_json, std::optional<std::string>(R"({"k":2})"));
  }
  const nlohmann::json detail = unit_detail_json("FOG-7", a.unit_campaigns("FOG-7"), AcceptanceLimits{});
  ASSERT_EQ(detail.at("calibrations").size(), 2U);
  EXPECT_EQ(detail.at("calibrations")[0].at("stand"), "stand-a");
  EXPECT_EQ(detail.at("calibrations")[1].at("stand"), "stand-b");
  EXPECT_EQ(detail.at("calibrations_counted"), 2);
  EXPECT_EQ(unit_list_json(a.unit_campaigns(std::nullopt), AcceptanceLimits{}).at("imus").size(), 2U);

  LimitsFile limits_a(a, "the lab's registry");
  const nlohmann::json doc = {{"format", "imucal-limits/1"},
                              {"part_numbers", {{"FOG-3A", {{"gyro.bias_dph", {{"max_abs", 1.0}}}}}}}};
  limits_a.replace(doc, "ada");
  const AcceptanceLimits seen_by_b = limits_b.current();
  ASSERT_EQ(seen_by_b.parts.size(), 1U);
  EXPECT_TRUE(seen_by_b.parts.contains("FOG-3A"));
  EXPECT_EQ(limits_b.document(), limits_a.document());
  EXPECT_THROW(limits_a.replace({{"format", "imucal-limits/0"}}, "ada"), std::invalid_argument);
  EXPECT_EQ(limits_b.current().parts.size(), 1U);  // a refused document changes nothing
}

// The server restarted (a crash, a network break): the call that met the break fails as a database
// failure (is_database_failure: the request may be repeated), the next one connects again.
TEST_F(PostgresRegistrySchema, ConnectsAgainAfterTheServerWentAway) {
  PostgresRegistry registry(store_.conninfo(), "stand-a");
  registry.append_audit("ada", "a", "s", "{}", 1);
  ASSERT_TRUE(imucaltest::shared_postgres_server().restart());
  try {
    registry.audit_trail();
  } catch (const imucal::storage::StorageError& e) {
    EXPECT_TRUE(is_database_failure(e)) << e.what();
  }
  EXPECT_EQ(registry.audit_trail().size(), 1U);
  EXPECT_EQ(registry.append_audit("ada", "b", "s", "{}", 2).seq, 2);
}

// Issue 38's "the database away": the PostgreSQL server stopped under a stand (pg_ctl stop) and
// started again. Each call tries the server (call_retry_interval 0): no test waits on a clock.
class RegistryAway : public ::testing::Test {
 protected:
  void SetUp() override {
    const std::string problem = store_.open();
    if (problem.rfind("skip: ", 0) == 0) GTEST_SKIP() << problem.substr(6);
    ASSERT_EQ(problem, "");
    dir_ = imucaltest::test_tmp_dir() + "/registry-away-" + std::to_string(getpid()) + "-" +
           imucaltest::PostgresServer::unique_name("j");
    std::filesystem::remove_all(dir_);
    std::filesystem::create_directories(dir_);
    journal_ = dir_ + "/registry-journal.jsonl";
  }
  void TearDown() override {
    // The server is shared by the executable's tests: never left stopped by a failed one.
    if (dir_.empty()) return;  // skipped
    EXPECT_TRUE(imucaltest::shared_postgres_server().start_again());
    std::error_code ignored;
    std::filesystem::remove_all(dir_, ignored);
  }
  std::unique_ptr<JournaledRegistry> journaled() {
    JournaledRegistry::Options options;
    options.call_retry_interval = std::chrono::milliseconds(0);
    return std::make_unique<JournaledRegistry>(
        [conninfo = store_.conninfo()] { return std::make_unique<PostgresRegistry>(conninfo, "stand-a"); }, journal_,
        options);
  }
  // What the server holds, read past the journal.
  std::unique_ptr<PostgresRegistry> direct() { return std::make_unique<PostgresRegistry>(store_.conninfo(), "stand-a"); }
  static std::size_t lines_of(const std::string& path) {
    std::ifstream in(path);
    std::size_t n = 0;
    for (std::string line; std::getline(in, line);) ++n;
    return n;
  }
  static void expect_unreachable(const std::function<void()>& read, std::int64_t waiting) {
    try {
      read();
      ADD_FAILURE() << "a read answered with the server away";
    } catch (const imucal::storage::StorageError& e) {
      const std::string what = e.what();
      EXPECT_TRUE(is_database_failure(e)) << what;  // HTTP 503: to be repeated later
      EXPECT_NE(what.find("PostgreSQL server"), std::string::npos) << what;
      EXPECT_NE(what.find("unreachable"), std::string::npos) << what;
      EXPECT_NE(what.find(std::to_string(waiting) + " writes"), std::string::npos) << what;
    }
  }
  PostgresStore store_;
  std::string dir_;
  std::string journal_;
};

TEST_F(RegistryAway, WritesWaitInTheJournalAndArriveOnceInOrderWhenTheServerReturns) {
  auto reg = journaled();
  EXPECT_TRUE(reg->reachable());
  EXPECT_EQ(reg->append_audit("ada", "before", "s", "{}", 1000).seq, 1);
  ASSERT_TRUE(imucaltest::shared_postgres_server().stop_for_a_while());

  const AuditEntry waiting = reg->append_audit("ada", "away.1", "campaign 1", R"({"n":1})", 2000);
  EXPECT_EQ(waiting.seq, 0);  // not chained yet: the head is on the server
  EXPECT_EQ(waiting.t_ms, 2000);
  EXPECT_EQ(waiting.sha256, "");
  const auto certificate = certificate_row(1, 1);
  reg->insert_issued(certificate);
  reg->insert_overdue_override({3, 42, "ada", "customer waits", "[]", "the rate table ..."});
  EXPECT_TRUE(reg->insert_issued_page({certificate.number, "<html>1</html>", "h1", 5, "ada"}));
  reg->append_audit("bob", "away.2", "campaign 1", "{}", 3000);
  EXPECT_FALSE(reg->reachable());
  EXPECT_EQ(reg->pending_writes(), 5);
  EXPECT_EQ(lines_of(journal_), 6U);  // the header and the five writes
  expect_unreachable([&] { reg->audit_trail(); }, 5);
  expect_unreachable([&] { reg->issued(certificate.number); }, 5);
  expect_unreachable([&] { reg->next_certificate_sequence(); }, 5);

  ASSERT_TRUE(imucaltest::shared_postgres_server().start_again());
  EXPECT_TRUE(reg->retry());
  EXPECT_TRUE(reg->reachable());
  EXPECT_EQ(reg->pending_writes(), 0);
  EXPECT_EQ(lines_of(journal_), 1U);
  EXPECT_TRUE(reg->retry());  // nothing again
  const AuditChain chain = reg->audit_chain();
  const auto& trail = chain.entries;
  ASSERT_EQ(trail.size(), 3U);
  EXPECT_EQ(trail[1].action, "away.1");
  EXPECT_EQ(trail[1].t_ms, 2000);  // the time it happened, not of its replay
  EXPECT_EQ(trail[2].action, "away.2");
  EXPECT_EQ(trail[2].t_ms, 3000);
  const AuditCheck check = check_audit_chain(chain);
  EXPECT_TRUE(check.ok()) << check.message;
  EXPECT_EQ(reg->issued_history(1).size(), 1U);
  EXPECT_EQ(reg->overdue_override(3).value_or(OverdueOverrideRow{}).by, "ada");
  EXPECT_EQ(reg->issued_page(certificate.number, true).value_or(IssuedPageRow{}).html, "<html>1</html>");
  EXPECT_EQ(reg->append_audit("ada", "after", "s", "{}", 4000).seq, 4);
}

// A reply lost on its way back after the server committed a write (the connection broke between
// the commit and its answer): the stand journals it, and its replay finds it applied by its key:
// the audit entry and the calibration arrive once (before: the entry was chained twice).
TEST_F(RegistryAway, AWriteWhoseReplyWasLostArrivesOnce) {
  bool lose_next_reply = false;
  JournaledRegistry::Options options;
  options.call_retry_interval = std::chrono::milliseconds(0);
  options.after_direct_write = [&] {
    if (std::exchange(lose_next_reply, false))
      throw imucal::storage::pg::PgError("registry: the reply was lost (test)", "", true);
  };
  auto reg = std::make_unique<JournaledRegistry>(
      [conninfo = store_.conninfo()] { return std::make_unique<PostgresRegistry>(conninfo, "stand-a"); }, journal_,
      options);
  ASSERT_TRUE(reg->reachable());
  EXPECT_EQ(reg->append_audit("ada", "first", "s", "{}", 1000).seq, 1);
  lose_next_reply = true;
  (void)reg->append_audit("ada", "reply.lost", "s", "{}", 2000);
  EXPECT_FALSE(reg->reachable());  // taken for the server's absence: journaled
  EXPECT_EQ(reg->pending_writes(), 1);
  lose_next_reply = true;
  CampaignRow row;
  row.id = 7;
  row.name = "lost reply";
  row.imu_serial = "LOST-1";
  reg->record_calibration(row);  // the entry replayed first (found applied), then this one's reply lost
  EXPECT_EQ(reg->pending_writes(), 1);
  EXPECT_TRUE(reg->retry());
  EXPECT_EQ(reg->pending_writes(), 0);
  const AuditChain chain = direct()->audit_chain();
  ASSERT_EQ(chain.entries.size(), 2U) << "the entry whose reply was lost was applied again";
  EXPECT_EQ(chain.entries[1].action, "reply.lost");
  EXPECT_TRUE(check_audit_chain(chain).ok());
  EXPECT_EQ(direct()->unit_campaigns(std::string("LOST-1")).size(), 1U);
  EXPECT_EQ(reg->append_audit("ada", "after", "s", "{}", 3000).seq, 3);
}

// The lab's accounts put and removed while the server is away arrive in order, with the time
// they were changed (written by helper-27's branch `users`, adapted).
TEST_F(RegistryAway, AccountsPutAndRemovedWhileTheServerIsAwayArriveInOrder) {
  ASSERT_TRUE(imucaltest::shared_postgres_server().stop_for_a_while());
  auto reg = journaled();
  reg->put_user({"grace", "viewer", "$hash", 1000, "ada"});
  reg->put_user({"linus", "viewer", "$hash", 2000, "ada"});
  EXPECT_TRUE(reg->remove_user("linus"));
  EXPECT_EQ(reg->pending_writes(), 3);
  expect_unreachable([&] { reg->users(); }, 3);
  ASSERT_TRUE(imucaltest::shared_postgres_server().start_again());
  EXPECT_TRUE(reg->retry());
  EXPECT_EQ(reg->pending_writes(), 0);
  const auto users = direct()->users();
  ASSERT_EQ(users.size(), 1U);
  EXPECT_EQ(users[0].name, "grace");
  EXPECT_EQ(users[0].changed_ms, 1000);
  EXPECT_EQ(users[0].changed_by, "ada");
}

// A unit's calibration recorded twice while the server is away (the run's end, then an
// operator's acceptance) and the limits put meanwhile arrive once, in order: the server has the
// later row. The limits last read judge meanwhile.
TEST_F(RegistryAway, CalibrationsAndLimitsWaitInTheJournalAndArriveInOrder) {
  auto reg = journaled();
  LimitsFile limits(*reg, "the lab's registry");
  const nlohmann::json doc = {{"format", "imucal-limits/1"},
                              {"part_numbers", {{"FOG-3A", {{"gyro.bias_dph", {{"max_abs", 1.0}}}}}}}};
  limits.replace(doc, "ada");
  ASSERT_TRUE(imucaltest::shared_postgres_server().stop_for_a_while());
  CampaignRow row = calibration_row(4, "FOG-7", 1000, R"({"k":1})");
  row.complete = false;  // stopped early: partial
  reg->record_calibration(row);
  row.accepted_reason = "enough positions";
  row.accepted_by = "ada";
  reg->record_calibration(row);
  const nlohmann::json looser = {{"format", "imucal-limits/1"},
                                 {"part_numbers", {{"FOG-3A", {{"gyro.bias_dph", {{"max_abs", 2.0}}}}}}}};
  limits.replace(looser, "bob");
  EXPECT_EQ(reg->pending_writes(), 3);
  expect_unreachable([&] { reg->unit_campaigns("FOG-7"); }, 3);
  EXPECT_EQ(limits.document(), limits_to_json(limits_from_json(looser)));  // as put, while away

  ASSERT_TRUE(imucaltest::shared_postgres_server().start_again());
  EXPECT_TRUE(reg->retry());
  const auto server = direct();
  const auto history = server->unit_campaigns("FOG-7");
  ASSERT_EQ(history.size(), 1U);
  EXPECT_EQ(history[0].accepted_reason, std::optional<std::string>("enough positions"));
  EXPECT_EQ(history[0].stand, "stand-a");
  LimitsFile on_server(*server, "the lab's registry");
  EXPECT_EQ(on_server.document(), limits_to_json(limits_from_json(looser)));
}

// A crash after some writes were applied and before the journal was trimmed: the journal as it
// was before the replay, put back, replayed by a new registry; and a write journaled behind them.
TEST_F(RegistryAway, AReplayRepeatedAfterACrashAppliesNothingTwice) {
  ASSERT_TRUE(imucaltest::shared_postgres_server().stop_for_a_while());
  {
    auto reg = journaled();  // the server away from the start: no error
    EXPECT_FALSE(reg->reachable());
    reg->append_audit("ada", "away.1", "s", "{}", 1000);
    reg->insert_issued(certificate_row(1, 1));
    reg->append_audit("ada", "away.2", "s", "{}", 2000);
    std::filesystem::copy_file(journal_, journal_ + ".before-replay");
    ASSERT_TRUE(imucaltest::shared_postgres_server().start_again());
    EXPECT_TRUE(reg->retry());
    EXPECT_EQ(reg->audit_trail().size(), 2U);
  }
  std::filesystem::rename(journal_ + ".before-replay", journal_);
  ASSERT_TRUE(imucaltest::shared_postgres_server().stop_for_a_while());
  {
    auto reg = journaled();
    EXPECT_EQ(reg->pending_writes(), 3);
    reg->append_audit("bob", "away.3", "s", "{}", 3000);  // numbered after the three
    ASSERT_TRUE(imucaltest::shared_postgres_server().start_again());
    EXPECT_TRUE(reg->retry());
    EXPECT_EQ(reg->pending_writes(), 0);
  }
  const auto server = direct();
  const AuditChain chain = server->audit_chain();
  const auto& trail = chain.entries;
  ASSERT_EQ(trail.size(), 3U);
  EXPECT_EQ(trail[0].action, "away.1");
  EXPECT_EQ(trail[1].action, "away.2");
  EXPECT_EQ(trail[2].action, "away.3");
  EXPECT_TRUE(check_audit_chain(chain).ok());
  EXPECT_EQ(server->issued_history(1).size(), 1U);
  EXPECT_FALSE(std::filesystem::exists(dir_ + "/registry-journal-refused.jsonl"));  // no duplicate refused
}

// A stand stopped with writes waiting: the next imucald replays them once the server answers
// (at once when it answers at the start).
TEST_F(RegistryAway, AJournalLeftAtShutdownIsReplayedByTheNextStart) {
  ASSERT_TRUE(imucaltest::shared_postgres_server().stop_for_a_while());
  {
    auto reg = journaled();
    reg->append_audit("ada", "away.1", "s", "{}", 1000);
    reg->insert_certificate({2, "LAB-2025-000007", 7, 1600000000000, "{}"});
  }
  {
    auto reg = journaled();  // started again, the server still away
    EXPECT_EQ(reg->pending_writes(), 2);
    EXPECT_FALSE(reg->reachable());
  }
  ASSERT_TRUE(imucaltest::shared_postgres_server().start_again());
  auto reg = journaled();
  EXPECT_EQ(reg->pending_writes(), 0);
  EXPECT_TRUE(reg->reachable());
  EXPECT_EQ(reg->audit_trail().size(), 1U);
  EXPECT_EQ(reg->certificate(2).value_or(CertificateRow{}).number, "LAB-2025-000007");
  EXPECT_EQ(reg->max_certificate_sequence(), 7);
}

// A refusal of the server is the caller's when it answers; one met at replay is kept beside the
// journal for the operator and does not hold the writes behind it.
TEST_F(RegistryAway, ARefusedWriteIsTheCallersOrSetAsideAtReplay) {
  auto reg = journaled();
  reg->insert_issued(certificate_row(1, 1));
  EXPECT_THROW(reg->insert_issued(certificate_row(1, 2)), imucal::storage::StorageError);  // the number is taken
  EXPECT_EQ(reg->pending_writes(), 0);
  ASSERT_TRUE(imucaltest::shared_postgres_server().stop_for_a_while());
  reg->insert_issued(certificate_row(1, 3));  // the same number again: refused at replay
  reg->append_audit("ada", "away", "s", "{}", 1000);
  ASSERT_TRUE(imucaltest::shared_postgres_server().start_again());
  EXPECT_TRUE(reg->retry());
  EXPECT_EQ(reg->audit_trail().size(), 1U);
  EXPECT_EQ(reg->issued(certificate_row(1, 1).number).value_or(IssuedCertificateRow{}).campaign_id, 1);
  EXPECT_EQ(lines_of(dir_ + "/registry-journal-refused.jsonl"), 1U);
}

// A stand registered while the server is away: its registration waits in the journal and arrives
// when the server returns; its heartbeats meanwhile are dropped (volatile), never journaled.
TEST_F(RegistryAway, AStandRegisteredWhileTheServerIsAwayArrivesWhenItReturns) {
  ASSERT_TRUE(imucaltest::shared_postgres_server().stop_for_a_while());
  auto reg = journaled();
  reg->register_stand(stand("stand-a", 1000));
  EXPECT_EQ(reg->pending_writes(), 1);
  EXPECT_TRUE(reg->report_stand_state("stand-a", R"({"run":{"id":1}})", 6000));
  EXPECT_TRUE(reg->report_stand_state("stand-a", R"({"run":{"id":1}})", 11000));
  EXPECT_EQ(reg->pending_writes(), 1);  // the heartbeats are not journaled
  expect_unreachable([&] { reg->stands(); }, 1);
  ASSERT_TRUE(imucaltest::shared_postgres_server().start_again());
  EXPECT_TRUE(reg->retry());
  EXPECT_EQ(reg->pending_writes(), 0);
  auto stands = reg->stands();
  ASSERT_EQ(stands.size(), 1U);
  EXPECT_EQ(stands[0].last_seen_ms, 1000);  // as registered: the dropped states never arrive
  EXPECT_TRUE(reg->report_stand_state("stand-a", R"({"run":{"id":2}})", 16000));
  stands = direct()->stands();
  ASSERT_EQ(stands.size(), 1U);
  EXPECT_EQ(stands[0].last_seen_ms, 16000);
  EXPECT_EQ(stands[0].state_json, R"({"run":{"id":2}})");
}

}  // namespace
