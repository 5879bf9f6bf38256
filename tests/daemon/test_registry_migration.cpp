// Issue 38: a stand's SQLite registry moved into a lab's PostgreSQL registry (imucal registry
// migrate, daemon/registry/registry_migration.hpp) and the lab's chain checked (imucal audit verify
// --postgresql): a stand's database with a few of each, migrated into a private server
// (tests/postgres_server.hpp; skipped, saying what is missing, without one), run twice, a dry run,
// the refusals, a tampered row found; and the command line end to end.
#include <gtest/gtest.h>

#include <fcntl.h>
#include <sys/file.h>
#include <sys/wait.h>
#include <unistd.h>

#include <array>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <memory>
#include <string>

#include "daemon/db/daemon_db.hpp"
#include "daemon/registry/postgres_registry.hpp"
#include "daemon/registry/registry_migration.hpp"
#include "storage/sqlite.hpp"
#include "tests/daemon/certificate_rows.hpp"
#include "tests/postgres_server.hpp"
#include "tests/test_paths.hpp"

using namespace imucal::daemon;

namespace {

constexpr const char* kLimits =
    R"({"format": "imucal-limits/1", "part_numbers": {"PN-100": {"gyro.bias_dph": {"max_abs": 1.0}}}})";

// A stand's certificate as issued: signed (the migration copies the signature too).
IssuedCertificateRow stand_certificate(std::int64_t sequence, std::int64_t campaign,
                                       std::optional<std::string> supersedes = std::nullopt) {
  IssuedCertificateRow r = imucaltest::certificate_row(sequence, campaign, std::move(supersedes));
  r.signed_json = R"({"signed":)" + std::to_string(sequence) + "}";
  return r;
}

// A stand's data directory whose daemon database holds a few of each thing the registry keeps.
class StandDir {
 public:
  StandDir() {
    dir_ = imucaltest::test_tmp_dir() + "/migrate-" + std::to_string(getpid()) + "-" +
           imucaltest::PostgresServer::unique_name("stand");
    std::filesystem::remove_all(dir_);
    std::filesystem::create_directories(dir_);
    db_ = std::make_unique<DaemonDb>(dir_ + "/imucald.db");
  }
  ~StandDir() {
    db_.reset();
    std::error_code ignored;
    std::filesystem::remove_all(dir_, ignored);
  }
  StandDir(const StandDir&) = delete;
  StandDir& operator=(const StandDir&) = delete;

  // Campaigns 1..4 (1 to 3 name units), a number of before issue 35 (campaign 4), three issued
  // certificates (the third supersedes the first), two printed pages, an overdue override, five
  // audit entries (one with numbers and text that must hash the same after the trip), a limits file.
  void fill() {
    db_->insert_campaign("c1", "{}", "direct", 10.0, "test", CampaignUnit{"FOG-1", "PN-100"});
    db_->insert_campaign("c2", "{}", "direct", 10.0, "test", CampaignUnit{"FOG-2", "PN-100"});
    db_->insert_campaign("c3", "{}", "direct", 10.0, "test", CampaignUnit{"FOG-1", "PN-100"});
    db_->insert_campaign("c4", "{}", "direct", 10.0, "test");
    db_->set_model(1, R"({"format":"imucal-imu-model/1"})");
    db_->insert_certificate({4, "LAB-2025-000001", 1, 1600000000000, R"({"devices":"sim"})"});
    db_->insert_issued(stand_certificate(2, 1));
    db_->insert_issued(stand_certificate(3, 2));
    db_->insert_issued(stand_certificate(4, 1, stand_certificate(2, 1).number));
    db_->insert_issued_page({stand_certificate(2, 1).number, "<html>2</html>", "h2", 5, "ada"});
    db_->insert_issued_page({stand_certificate(3, 2).number, "<html>3</html>", "h3", 6, "bob"});
    db_->insert_overdue_override({2, 7, "ada", "the table is fine", R"([{"instrument":"table"}])", "the rate table ..."});
    db_->append_audit("imucald", "service.started", "imucald", R"({"users":["ada"]})", 10);
    db_->append_audit("ada", "campaign.created", "campaign 1", R"({"x":0.1,"y":[1,2.5e-7,{"z":"é \"q\""}]})", 11);
    db_->append_audit("ada", "campaign.override_overdue", "campaign 2", R"({"reason":"the table is fine"})", 12);
    db_->append_audit("imucald", "certificate.issued", "LAB-2026-000004", "{}", 13);
    db_->append_audit("ada", "limits.replaced", "limits", R"({"before":{},"after":{"n":1}})", 14);
    db_->put_user({"grace", "viewer", "$argon2id$grace", 15, "ada"});  // a lab account of the stand's
    std::ofstream(dir_ + "/limits.json") << kLimits;
  }

  StandRegistrySource source(const std::string& stand = "stand-a") {
    StandRegistrySource s;
    s.db = db_.get();
    s.stand = stand;
    s.label = dir_;
    s.limits_json = kLimits;
    s.actor = "tester";
    return s;
  }
  DaemonDb& db() { return *db_; }
  const std::string& dir() const { return dir_; }
  // Closes the database (a tampered copy is edited past it; imucal opens it itself).
  void close() { db_.reset(); }

 private:
  std::string dir_;
  std::unique_ptr<DaemonDb> db_;
};

class RegistryMigration : public ::testing::Test {
 protected:
  void SetUp() override {
    IMUCALTEST_FRESH_POSTGRES_DATABASE(conninfo_, "migrate");
    stand_.fill();
  }
  std::unique_ptr<PostgresRegistry> lab(const std::string& stand = "stand-a") {
    return std::make_unique<PostgresRegistry>(conninfo_, stand);
  }
  LabAuditCheck verify_lab() {
    const RegistryAuditTrail trail = read_postgres_audit_trail(conninfo_);
    return check_lab_audit_chain(trail.entries, trail.head);
  }
  std::string conninfo_;
  StandDir stand_;
};

TEST_F(RegistryMigration, AStandsRegistryMovesInWholeAndASecondRunCopiesNothing) {
  // Another stand wrote to the lab's chain first: the migrated entries are new links after it.
  lab("stand-b")->append_audit("imucald", "service.started", "imucald", "{}", 1);
  auto reg = lab();
  const MigrationReport first = migrate_stand_registry(stand_.source(), *reg, false);
  EXPECT_EQ(first.count("certificate numbers (before issue 35)").copied, 1);
  EXPECT_EQ(first.count("issued certificates").copied, 3);
  EXPECT_EQ(first.count("printed pages").copied, 2);
  EXPECT_EQ(first.count("overdue overrides").copied, 1);
  EXPECT_EQ(first.count("calibrations").copied, 3);
  EXPECT_EQ(first.count("limits document").copied, 1);
  EXPECT_EQ(first.count("accounts").copied, 1);
  EXPECT_EQ(first.count("audit entries").copied, 5);
  EXPECT_EQ(first.first_lab_audit_seq, 2);
  EXPECT_EQ(first.last_lab_audit_seq, 7);  // and the migration's own entry
  EXPECT_EQ(first.skipped(), 0);

  // The contents, as the stand's imucald will read them from the lab.
  EXPECT_EQ(reg->certificate(4).value_or(CertificateRow{}).number, "LAB-2025-000001");
  const auto history = reg->issued_history(1);
  ASSERT_EQ(history.size(), 2U);
  EXPECT_EQ(history[0].superseded_by, stand_certificate(4, 1).number);
  EXPECT_EQ(history[1].supersedes, stand_certificate(2, 1).number);
  EXPECT_EQ(history[1].signed_json, stand_certificate(4, 1).signed_json);
  EXPECT_EQ(reg->current_issued(2).value_or(IssuedCertificateRow{}).content_json, stand_certificate(3, 2).content_json);
  EXPECT_EQ(reg->issued_page(stand_certificate(3, 2).number, true).value_or(IssuedPageRow{}).html, "<html>3</html>");
  EXPECT_EQ(reg->overdue_override(2).value_or(OverdueOverrideRow{}).reason, "the table is fine");
  const auto fog1 = reg->unit_campaigns(std::string("FOG-1"));
  ASSERT_EQ(fog1.size(), 2U);
  EXPECT_EQ(fog1[0].stand, "stand-a");
  EXPECT_EQ(fog1[0].model_json, R"({"format":"imucal-imu-model/1"})");
  EXPECT_EQ(reg->limits_document(), std::optional<std::string>(kLimits));
  ASSERT_EQ(reg->users().size(), 1U);
  EXPECT_EQ(reg->users()[0].password_hash, "$argon2id$grace");
  // The numbers go on past the stand's highest, from any stand.
  EXPECT_EQ(first.highest_sequence, 4);
  EXPECT_EQ(lab("stand-c")->next_certificate_sequence(), 5);

  // Each entry keeps its origin: the stand's old chain is checkable from the lab's.
  const auto trail = reg->audit_trail();
  ASSERT_EQ(trail.size(), 7U);
  const auto origin = migrated_origin(trail[2]);
  ASSERT_TRUE(origin);
  EXPECT_EQ(origin->stand, "stand-a");
  EXPECT_EQ(origin->original.seq, 2);
  EXPECT_EQ(origin->original.sha256, stand_.db().audit_trail()[1].sha256);
  EXPECT_EQ(trail[6].action, "registry.migrated");
  const LabAuditCheck check = verify_lab();
  EXPECT_TRUE(check.ok()) << check.lab.message;
  ASSERT_EQ(check.stands.size(), 1U);
  EXPECT_EQ(check.stands[0].first, "stand-a");
  EXPECT_EQ(check.stands[0].second.entries, 5);
  EXPECT_TRUE(check.stands[0].second.ok()) << check.stands[0].second.message;

  // Twice: nothing copied twice, and said so.
  const MigrationReport second = migrate_stand_registry(stand_.source(), *reg, false);
  EXPECT_EQ(second.copied(), 0);
  EXPECT_EQ(second.skipped(), first.copied());
  EXPECT_EQ(reg->audit_trail().size(), 7U);
  EXPECT_EQ(reg->issued_history(1).size(), 2U);

  // What the stand did since (it ran on before the move): only that is copied.
  stand_.db().insert_issued(stand_certificate(9, 3));
  stand_.db().append_audit("imucald", "certificate.issued", "LAB-2026-000009", "{}", 20);
  const MigrationReport third = migrate_stand_registry(stand_.source(), *reg, false);
  EXPECT_EQ(third.count("issued certificates").copied, 1);
  EXPECT_EQ(third.count("audit entries").copied, 1);
  EXPECT_EQ(third.count("audit entries").skipped, 5);
  EXPECT_EQ(lab("stand-c")->next_certificate_sequence(), 10);
  const LabAuditCheck again = verify_lab();
  EXPECT_TRUE(again.ok()) << again.lab.message;
  ASSERT_EQ(again.stands.size(), 1U);
  EXPECT_EQ(again.stands[0].second.entries, 6);
}

TEST_F(RegistryMigration, ADryRunCountsEverythingAndWritesNothing) {
  auto reg = lab();
  const MigrationReport dry = migrate_stand_registry(stand_.source(), *reg, true);
  EXPECT_TRUE(dry.dry_run);
  EXPECT_EQ(dry.count("issued certificates").copied, 3);
  EXPECT_EQ(dry.count("audit entries").copied, 5);
  EXPECT_EQ(dry.lab_sequence_after, 4);
  EXPECT_TRUE(reg->audit_trail().empty());
  EXPECT_FALSE(reg->issued(stand_certificate(2, 1).number));
  EXPECT_FALSE(reg->limits_document());
  EXPECT_EQ(reg->last_certificate_sequence(), 0);
  const auto lines = dry.lines();
  ASSERT_FALSE(lines.empty());
  EXPECT_NE(lines[1].find("would be copied"), std::string::npos) << lines[1];
}

TEST_F(RegistryMigration, ABrokenChainIsRefusedNamingItsFirstBadEntry) {
  const std::string path = stand_.dir() + "/imucald.db";
  stand_.close();
  {
    imucal::storage::sql::Connection db(path, imucal::storage::sql::Connection::Open::read_write, "test");
    db.exec("DROP TRIGGER audit_append_only; UPDATE audit SET actor = 'mallory' WHERE seq = 3");
  }
  DaemonDb db(path);
  StandRegistrySource source = stand_.source();
  source.db = &db;
  auto reg = lab();
  try {
    (void)migrate_stand_registry(source, *reg, false);
    FAIL() << "a broken chain was migrated";
  } catch (const MigrationError& e) {
    EXPECT_NE(std::string(e.what()).find("audit entry 3: changed after it was written"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find(stand_.dir()), std::string::npos) << e.what();
  }
  EXPECT_TRUE(reg->audit_trail().empty());
  EXPECT_TRUE(reg->unit_campaigns(std::nullopt).empty());
}

// Another stand's certificate holds a number of this stand's: the whole migration is refused,
// naming both, and nothing of it stays in the lab.
TEST_F(RegistryMigration, AConflictWithAnotherStandsRowCopiesNothing) {
  IssuedCertificateRow theirs = stand_certificate(3, 1);
  theirs.content_sha256 = "another";
  lab("stand-b")->insert_issued(theirs);
  auto reg = lab();
  try {
    (void)migrate_stand_registry(stand_.source(), *reg, false);
    FAIL() << "a conflicting certificate was migrated";
  } catch (const MigrationError& e) {
    const std::string what = e.what();
    EXPECT_NE(what.find("certificate LAB-2026-000003 (sequence 3, campaign 2)"), std::string::npos) << what;
    EXPECT_NE(what.find("content another"), std::string::npos) << what;
    EXPECT_NE(what.find("nothing was copied"), std::string::npos) << what;
  }
  EXPECT_FALSE(reg->issued(stand_certificate(2, 1).number));
  EXPECT_TRUE(reg->audit_trail().empty());
  EXPECT_FALSE(reg->certificate(4));
}

// The lab's chain is checked by the same rule as a stand's: a row changed past the trigger (as the
// superuser may) is found and named.
TEST_F(RegistryMigration, TheLabsChainIsCheckedAndATamperedRowFound) {
  auto reg = lab();
  (void)migrate_stand_registry(stand_.source(), *reg, false);
  reg->append_audit("ada", "limits.replaced", "limits", "{}", 30);
  ASSERT_TRUE(verify_lab().ok());
  {
    imucal::storage::pg::Connection superuser(conninfo_, "test");
    superuser.exec_script("ALTER TABLE audit DISABLE TRIGGER audit_append_only; "
                          "UPDATE audit SET actor = 'mallory' WHERE seq = 4; "
                          "ALTER TABLE audit ENABLE TRIGGER audit_append_only");
  }
  const LabAuditCheck edited = verify_lab();
  EXPECT_FALSE(edited.ok());
  EXPECT_EQ(edited.lab.first_bad, std::optional<std::int64_t>(4));
  EXPECT_NE(edited.lab.message.find("audit entry 4: changed after it was written"), std::string::npos)
      << edited.lab.message;
  // The stand's own chain, read from the origins, fails at its own entry of that row.
  ASSERT_EQ(edited.stands.size(), 1U);
  EXPECT_EQ(edited.stands[0].second.first_bad, std::optional<std::int64_t>(4));
}

// The last entries deleted (the trigger disabled) no longer reach the head recorded beside them.
TEST_F(RegistryMigration, TheLabsLastEntriesDeletedAreFound) {
  auto reg = lab();
  (void)migrate_stand_registry(stand_.source(), *reg, false);
  {
    imucal::storage::pg::Connection superuser(conninfo_, "test");
    superuser.exec_script("ALTER TABLE audit DISABLE TRIGGER audit_append_only; "
                          "DELETE FROM audit WHERE seq = (SELECT MAX(seq) FROM audit)");
  }
  const LabAuditCheck tail = verify_lab();
  EXPECT_FALSE(tail.ok());
  EXPECT_NE(tail.lab.message.find("entries at the end were deleted"), std::string::npos) << tail.lab.message;
}

// ---- The command line end to end ---------------------------------------------------------------

struct CliResult {
  int status = -1;
  std::string output;  // stdout and stderr
};

CliResult run_imucal(const std::string& args) {
  const std::string cmd = imucaltest::program("imucal") + " " + args + " 2>&1";
  CliResult r;
  FILE* p = popen(cmd.c_str(), "r");
  if (p == nullptr) return r;
  std::array<char, 4096> buf{};
  while (std::fgets(buf.data(), buf.size(), p) != nullptr) r.output += buf.data();
  const int status = pclose(p);
  r.status = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  return r;
}

std::string shell_quoted(const std::string& s) { return "'" + s + "'"; }

TEST_F(RegistryMigration, TheCommandLineMovesAStandInOnceAndVerifiesTheLabsChain) {
  stand_.close();
  const std::string dir = shell_quoted(stand_.dir());
  const std::string to = " --to " + shell_quoted(conninfo_) + " --stand stand-a --operator tester";
  CliResult r = run_imucal("registry migrate " + dir + to + " --dry-run");
  ASSERT_EQ(r.status, 0) << r.output;
  EXPECT_NE(r.output.find("dry run, nothing is written"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("issued certificates: 3 would be copied"), std::string::npos) << r.output;
  EXPECT_TRUE(lab()->audit_trail().empty());

  r = run_imucal("registry migrate " + dir + to);
  ASSERT_EQ(r.status, 0) << r.output;
  EXPECT_NE(r.output.find("audit entries: 5 copied, 0 skipped"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("limits document: 1 copied"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("the lab's next number is 5"), std::string::npos) << r.output;

  r = run_imucal("registry migrate " + dir + to);
  ASSERT_EQ(r.status, 0) << r.output;
  EXPECT_NE(r.output.find("nothing to copy"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("issued certificates: 0 copied, 3 skipped"), std::string::npos) << r.output;

  r = run_imucal("audit verify --postgresql " + shell_quoted(conninfo_));
  EXPECT_EQ(r.status, 0) << r.output;
  EXPECT_NE(r.output.find("OK: the lab's audit trail intact: 6 entries"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("OK: stand 'stand-a''s own chain, as migrated into the lab's: audit trail intact: 5 entries"),
            std::string::npos)
      << r.output;
  {
    imucal::storage::pg::Connection superuser(conninfo_, "test");
    superuser.exec_script("ALTER TABLE audit DISABLE TRIGGER audit_append_only; "
                          "UPDATE audit SET details_json = '{}' WHERE seq = 2");
  }
  r = run_imucal("audit verify --postgresql " + shell_quoted(conninfo_));
  EXPECT_EQ(r.status, 1) << r.output;
  EXPECT_NE(r.output.find("FAILED: the lab's audit entry 2: changed after it was written"), std::string::npos)
      << r.output;
  EXPECT_NE(r.output.find("(written by stand 'stand-a')"), std::string::npos) << r.output;
}

TEST_F(RegistryMigration, TheCommandLineNamesWhatIsWrong) {
  stand_.close();
  const std::string dir = shell_quoted(stand_.dir());
  // A server away, a connection string that is none: named as --to's, nothing else said.
  CliResult r = run_imucal("registry migrate " + dir + " --to 'host=/nonexistent/socket dbname=x' --stand s");
  EXPECT_EQ(r.status, 1) << r.output;
  EXPECT_NE(r.output.find("the lab's registry (--to): registry: cannot connect to the PostgreSQL server"),
            std::string::npos)
      << r.output;
  r = run_imucal("registry migrate " + dir + " --to 'no such thing' --stand s");
  EXPECT_EQ(r.status, 1) << r.output;
  EXPECT_NE(r.output.find("the lab's registry (--to)"), std::string::npos) << r.output;
  // A registry newer than this imucal.
  {
    auto reg = lab();
    imucal::storage::pg::Connection raw(conninfo_, "test");
    raw.exec("UPDATE registry_schema SET version = $1", {99});
  }
  r = run_imucal("registry migrate " + dir + " --to " + shell_quoted(conninfo_) + " --stand s");
  EXPECT_EQ(r.status, 1) << r.output;
  EXPECT_NE(r.output.find("schema version 99, newer than this imucald supports"), std::string::npos) << r.output;
  r = run_imucal("audit verify --postgresql " + shell_quoted(conninfo_));
  EXPECT_EQ(r.status, 1) << r.output;
  EXPECT_NE(r.output.find("schema version 99"), std::string::npos) << r.output;
  // No data directory; an imucald running on it; neither DATA_DIR nor --postgresql.
  r = run_imucal("registry migrate /no/such/dir --to " + shell_quoted(conninfo_));
  EXPECT_EQ(r.status, 1) << r.output;
  EXPECT_NE(r.output.find("no imucald database in '/no/such/dir'"), std::string::npos) << r.output;
  const int fd = ::open((stand_.dir() + "/imucald.lock").c_str(), O_RDWR | O_CREAT | O_CLOEXEC, 0600);
  ASSERT_GE(fd, 0);
  ASSERT_EQ(::flock(fd, LOCK_EX | LOCK_NB), 0);
  r = run_imucal("registry migrate " + dir + " --to " + shell_quoted(conninfo_) + " --stand s");
  ::close(fd);
  EXPECT_EQ(r.status, 1) << r.output;
  EXPECT_NE(r.output.find("an imucald is running on the data directory"), std::string::npos) << r.output;
  r = run_imucal("audit verify");
  EXPECT_EQ(r.status, 2) << r.output;
  EXPECT_NE(r.output.find("give DATA_DIR or --postgresql"), std::string::npos) << r.output;
}

// docs/daemon.md "A lab of stands from scratch": the roles as documented there. The owner role
// creates and migrates the schema (imucal registry init, imucal registry migrate); the stands' role
// reads and writes rows only, cannot create the schema (told to ask the owner) and cannot switch
// a trigger off.
TEST_F(RegistryMigration, TheOwnerMigratesTheSchemaAndTheStandsRoleWritesRowsOnly) {
  auto& server = imucaltest::shared_postgres_server();
  const std::string db = imucaltest::PostgresServer::unique_name("lab");
  const std::string owner = imucaltest::PostgresServer::unique_name("imucal_owner");
  const std::string stand_role = imucaltest::PostgresServer::unique_name("imucal_stand");
  const auto as = [&](const std::string& user) {
    return "host=" + server.socket_dir() + " port=5432 dbname=" + db + " user=" + user;
  };
  {
    imucal::storage::pg::Connection admin(server.conninfo("postgres"), "test");
    admin.exec_script("CREATE ROLE " + owner + " LOGIN");
    admin.exec_script("CREATE ROLE " + stand_role + " LOGIN");
    admin.exec_script("CREATE DATABASE " + db + " OWNER " + owner);
  }
  {
    imucal::storage::pg::Connection superuser(as("imucal"), "test");
    superuser.exec_script("ALTER DEFAULT PRIVILEGES FOR ROLE " + owner + " IN SCHEMA public GRANT SELECT, INSERT, "
                          "UPDATE, DELETE ON TABLES TO " + stand_role + "; ALTER DEFAULT PRIVILEGES FOR ROLE " + owner +
                          " IN SCHEMA public GRANT USAGE, SELECT ON SEQUENCES TO " + stand_role);
  }
  // Before the owner made the schema, a stand is told whom to ask.
  try {
    PostgresRegistry early(as(stand_role), "stand-a");
    FAIL() << "the stands' role created the schema";
  } catch (const DbError& e) {
    EXPECT_NE(std::string(e.what()).find("imucal registry init"), std::string::npos) << e.what();
  }
  CliResult r = run_imucal("registry init --to " + shell_quoted(as(owner)));
  ASSERT_EQ(r.status, 0) << r.output;
  EXPECT_NE(r.output.find("schema version " + std::to_string(PostgresRegistry::kSchemaVersion)), std::string::npos)
      << r.output;
  stand_.close();
  r = run_imucal("registry migrate " + shell_quoted(stand_.dir()) + " --to " + shell_quoted(as(owner)) + " --stand stand-a");
  ASSERT_EQ(r.status, 0) << r.output;

  // A stand's every write, as its role.
  PostgresRegistry reg(as(stand_role), "stand-a");
  const std::int64_t n = reg.next_certificate_sequence();
  EXPECT_EQ(n, 5);
  reg.insert_issued(stand_certificate(n, 2, stand_certificate(3, 2).number));
  EXPECT_TRUE(reg.insert_issued_page({stand_certificate(n, 2).number, "<html/>", "h", 1, "ada"}));
  reg.insert_overdue_override({3, 1, "ada", "why", "[]", "text"});
  reg.remove_overdue_override(3);
  reg.append_audit("ada", "campaign.command", "campaign 3", "{}", std::nullopt);
  reg.put_limits_document(kLimits, "ada");
  CampaignRow row;
  row.id = 7;
  row.imu_serial = "FOG-7";
  reg.record_calibration(row);
  reg.register_stand(StandRow{"stand-a", "sim", "http://a:8080", "test", 5000, 1, 1, "{}"});
  EXPECT_TRUE(reg.report_stand_state("stand-a", "{}", 2));
  EXPECT_TRUE(reg.apply_once("journal-1", 1, [] {}));
  // What only the owner may: a trigger switched off.
  imucal::storage::pg::Connection stand_connection(as(stand_role), "test");
  EXPECT_THROW(stand_connection.exec("ALTER TABLE audit DISABLE TRIGGER audit_append_only"),
               imucal::storage::pg::PgError);
  r = run_imucal("audit verify --postgresql " + shell_quoted(as(stand_role)));
  EXPECT_EQ(r.status, 0) << r.output;
}

}  // namespace
