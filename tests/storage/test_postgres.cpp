// The PostgreSQL layer (storage/postgres.hpp) against a private server (tests/postgres_server.hpp):
// parameters and NULLs, transactions, and failures that name the statement and the server's message.
#include <gtest/gtest.h>

#include <string>

#include "storage/postgres.hpp"
#include "tests/postgres_server.hpp"

namespace pg = imucal::storage::pg;

namespace {

class PostgresLayer : public ::testing::Test {
 protected:
  static imucaltest::PostgresServer& server() { return imucaltest::shared_postgres_server(); }
  void SetUp() override { IMUCALTEST_FRESH_POSTGRES_DATABASE(conninfo_, "layer"); }
  std::string conninfo_;
};

TEST_F(PostgresLayer, ParametersAndNullsGoThereAndBack) {
  pg::Connection c(conninfo_, "test database");
  c.exec_script("CREATE TABLE t(i BIGINT, d DOUBLE PRECISION, s TEXT, n TEXT)");
  // A value that would break a spliced statement goes through as a parameter.
  const std::string tricky = "it's'); DROP TABLE t; --";
  c.exec("INSERT INTO t VALUES ($1, $2, $3, $4)", {std::int64_t{-9007199254740993}, 0.1, tricky, std::nullopt});
  const pg::Result r = c.exec("SELECT i, d, s, n FROM t");
  ASSERT_EQ(r.rows(), 1);
  EXPECT_EQ(r.int64(0, 0), -9007199254740993);
  EXPECT_EQ(r.number(0, 1), 0.1);
  EXPECT_EQ(r.text(0, 2), tricky);
  EXPECT_TRUE(r.is_null(0, 3));
  EXPECT_EQ(r.optional_text(0, 3), std::nullopt);
  EXPECT_EQ(c.exec("UPDATE t SET n = $1", {"x"}).affected(), 1);
}

TEST_F(PostgresLayer, ATransactionLeftWithoutCommitIsRolledBack) {
  pg::Connection c(conninfo_, "test database");
  c.exec_script("CREATE TABLE t(i BIGINT PRIMARY KEY)");
  try {
    pg::Transaction txn(c);
    c.exec("INSERT INTO t VALUES ($1)", {1});
    EXPECT_TRUE(c.in_transaction());
    c.exec("INSERT INTO t VALUES ($1)", {1});  // a unique violation: the transaction is left
    FAIL() << "a duplicate key was accepted";
  } catch (const pg::PgError& e) {
    EXPECT_TRUE(e.unique_violation()) << e.what();
    EXPECT_FALSE(e.connection_lost());
  }
  EXPECT_FALSE(c.in_transaction());
  EXPECT_EQ(c.exec("SELECT COUNT(*) FROM t").int64(0, 0), 0);
  {
    pg::Transaction txn(c);
    c.exec("INSERT INTO t VALUES ($1)", {2});
    txn.commit();
  }
  EXPECT_EQ(c.exec("SELECT COUNT(*) FROM t").int64(0, 0), 1);
}

TEST_F(PostgresLayer, AFailureNamesTheDatabaseTheStatementAndTheServersMessage) {
  pg::Connection c(conninfo_, "test database");
  try {
    c.exec("SELECT * FROM no_such_table WHERE x = $1", {1});
    FAIL() << "no error";
  } catch (const pg::PgError& e) {
    const std::string what = e.what();
    EXPECT_NE(what.find("test database"), std::string::npos) << what;
    EXPECT_NE(what.find("SELECT * FROM no_such_table WHERE x = $1"), std::string::npos) << what;
    EXPECT_NE(what.find("relation \"no_such_table\" does not exist"), std::string::npos) << what;
    EXPECT_EQ(e.sqlstate(), "42P01");
  }
}

TEST_F(PostgresLayer, AServerThatCannotBeReachedIsSaidSo) {
  try {
    pg::Connection c("host=" + server().socket_dir() + "/nowhere dbname=x user=imucal connect_timeout=2", "registry");
    FAIL() << "connected to nothing";
  } catch (const pg::PgError& e) {
    EXPECT_TRUE(e.connection_lost());
    EXPECT_NE(std::string(e.what()).find("registry: cannot connect to the PostgreSQL server"), std::string::npos)
        << e.what();
  }
}

}  // namespace
