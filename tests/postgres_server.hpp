// A private PostgreSQL server for the tests (issue 38): Debian's initdb and pg_ctl make a cluster in
// a temporary directory and start it listening on a unix socket in that directory only (no TCP
// port, so parallel tests never clash), trusted for local connections; it is stopped and removed
// when the object goes. initdb refuses to run as root: a test run as root runs the server as an
// unprivileged user (IMUCAL_PG_USER, else "nobody") through runuser, the directory handed to it.
//
// When the binaries are absent, skip_reason() says what is missing (the tests GTEST_SKIP with it);
// when they are there and the server does not start, error() says why (the tests fail).
#pragma once

#include <pwd.h>
#include <unistd.h>

#include <atomic>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

#include "storage/postgres.hpp"

namespace imucaltest {

class PostgresServer {
 public:
  // `durable`: the server syncs its commits to the disk as a lab's server does (the registry's
  // benchmark, bench/bench_registry.cpp); by default not (a test's data is scratch).
  explicit PostgresServer(bool durable = false) : durable_(durable) {
    if (!find_binaries() || !choose_user()) return;
    start();
  }
  ~PostgresServer() { stop(); }
  PostgresServer(const PostgresServer&) = delete;
  PostgresServer& operator=(const PostgresServer&) = delete;

  bool running() const { return running_; }
  const std::string& skip_reason() const { return skip_reason_; }
  const std::string& error() const { return error_; }
  const std::string& socket_dir() const { return dir_; }
  const std::string& run_as() const { return user_; }  // empty: the test's own user

  // Stops the server at once (as a crash would) and starts it again: its connections break.
  bool restart() {
    if (!running_) return false;
    return run("'" + bin_ + "/pg_ctl' -D '" + dir_ + "/data' -l '" + dir_ + "/server.log' -m immediate -w -t 60 -o '" + options() + "' restart");
  }
  // Stops the server (a lab's server going away) until start_again(): its connections break and
  // new ones are refused.
  bool stop_for_a_while() {
    if (!running_) return false;
    running_ = !run("'" + bin_ + "/pg_ctl' -D '" + dir_ + "/data' -m fast -w -t 60 stop");
    return !running_;
  }
  bool start_again() {
    if (running_) return true;
    running_ = run("'" + bin_ + "/pg_ctl' -D '" + dir_ + "/data' -l '" + dir_ + "/server.log' -w -t 60 -o '" +
                   options() + "' start");
    return running_;
  }
  // A connection string to database `name` of this server.
  std::string conninfo(const std::string& name) const {
    return "host=" + dir_ + " port=" + std::to_string(kPort) + " user=imucal dbname=" + name;
  }
  // A fresh, empty database; its connection string. `name` is made of [a-z0-9_] by the caller.
  std::string create_database(const std::string& name) {
    imucal::storage::pg::Connection admin(conninfo("postgres"), "test server");
    admin.exec_script("DROP DATABASE IF EXISTS " + name);
    admin.exec_script("CREATE DATABASE " + name);
    return conninfo(name);
  }
  // A name no other database of this process took: "<prefix>_<n>".
  static std::string unique_name(const std::string& prefix) {
    static std::atomic<int> n{0};
    return prefix + "_" + std::to_string(++n);
  }

 private:
  static constexpr int kPort = 5432;  // only names the socket file (.s.PGSQL.5432) in dir_

  bool find_binaries() {
    std::vector<std::filesystem::path> candidates;
    if (const char* env = std::getenv("IMUCAL_PG_BINDIR")) candidates.emplace_back(env);
    std::error_code ec;
    for (const auto& entry : std::filesystem::directory_iterator("/usr/lib/postgresql", ec))
      candidates.push_back(entry.path() / "bin");
    for (const auto& c : candidates) {
      if (std::filesystem::exists(c / "initdb") && std::filesystem::exists(c / "pg_ctl")) {
        bin_ = c.string();
        return true;
      }
    }
    skip_reason_ = "PostgreSQL's initdb and pg_ctl were not found (in $IMUCAL_PG_BINDIR or "
                   "/usr/lib/postgresql/*/bin): install the package postgresql (scripts/install-deps.sh)";
    return false;
  }

  bool choose_user() {
    if (geteuid() != 0) return true;
    const char* env = std::getenv("IMUCAL_PG_USER");
    const std::string user = env != nullptr && *env != '\0' ? env : "nobody";
    passwd* pw = getpwnam(user.c_str());
    if (pw == nullptr) {
      skip_reason_ = "the tests run as root, whom initdb refuses, and the user '" + user +
                     "' to run the PostgreSQL server as does not exist (set IMUCAL_PG_USER)";
      return false;
    }
    for (const char* runuser : {"/usr/sbin/runuser", "/sbin/runuser", "/usr/bin/runuser"}) {
      if (std::filesystem::exists(runuser)) {
        prefix_ = std::string(runuser) + " -u " + user + " -- ";
        user_ = user;
        uid_ = pw->pw_uid;
        gid_ = pw->pw_gid;
        return true;
      }
    }
    skip_reason_ = "the tests run as root, whom initdb refuses, and runuser (util-linux) is missing to run the "
                   "PostgreSQL server as '" + user + "'";
    return false;
  }

  // Runs `command` (output appended to the directory's setup.log); true when it succeeded.
  bool run(const std::string& command) {
    const std::string line = prefix_ + command + " >>'" + dir_ + "/setup.log' 2>&1";
    return std::system(line.c_str()) == 0;
  }

  std::string log_tail() const {
    std::ifstream in(dir_ + "/setup.log");
    std::stringstream text;
    text << in.rdbuf();
    const std::string all = text.str();
    return all.size() > 1500 ? all.substr(all.size() - 1500) : all;
  }

  void start() {
    // Under /tmp: a unix socket's path is limited to 107 bytes, a build directory may be deep.
    std::string templ = "/tmp/imucal-pg-XXXXXX";
    if (mkdtemp(templ.data()) == nullptr) {
      error_ = "cannot create a temporary directory under /tmp";
      return;
    }
    dir_ = templ;
    if (!user_.empty() && chown(dir_.c_str(), uid_, gid_) != 0) {
      error_ = "cannot hand " + dir_ + " to the user '" + user_ + "'";
      return;
    }
    if (!run("'" + bin_ + "/initdb' -D '" + dir_ + "/data' -U imucal -A trust --no-sync -E UTF8 --locale=C")) {
      error_ = "initdb failed in " + dir_ + ":\n" + log_tail();
      return;
    }
    if (!run("'" + bin_ + "/pg_ctl' -D '" + dir_ + "/data' -l '" + dir_ + "/server.log' -w -t 60 -o '" + options() +
             "' start")) {
      error_ = "pg_ctl start failed in " + dir_ + ":\n" + log_tail();
      return;
    }
    running_ = true;
  }

  // The server's options: its socket in dir_ only (no TCP), no fsync unless durable.
  std::string options() const {
    return "-k " + dir_ + " -c listen_addresses=" + (durable_ ? "" : " -F") + " -p " + std::to_string(kPort);
  }

  void stop() {
    if (running_) run("'" + bin_ + "/pg_ctl' -D '" + dir_ + "/data' -m immediate -w stop");
    running_ = false;
    if (!dir_.empty()) {
      std::error_code ignored;
      std::filesystem::remove_all(dir_, ignored);
    }
  }

  std::string bin_, dir_, prefix_, user_, skip_reason_, error_;
  uid_t uid_ = 0;
  gid_t gid_ = 0;
  bool running_ = false;
  bool durable_ = false;
};

// The test executable's one private server, started at its first use; its tests take a database
// each (IMUCALTEST_FRESH_POSTGRES_DATABASE).
inline PostgresServer& shared_postgres_server() {
  static PostgresServer server;
  return server;
}

}  // namespace imucaltest

// In a test or SetUp: skips it, saying what is missing, without PostgreSQL's binaries; fails it
// when the server did not start; else sets `conninfo` to a fresh database "<prefix>_<n>" of
// shared_postgres_server().
#define IMUCALTEST_FRESH_POSTGRES_DATABASE(conninfo, prefix)                                          \
  do {                                                                                                \
    ::imucaltest::PostgresServer& imucaltest_server = ::imucaltest::shared_postgres_server();         \
    if (!imucaltest_server.skip_reason().empty()) GTEST_SKIP() << imucaltest_server.skip_reason();    \
    ASSERT_TRUE(imucaltest_server.running()) << imucaltest_server.error();                            \
    (conninfo) = imucaltest_server.create_database(::imucaltest::PostgresServer::unique_name(prefix)); \
  } while (false)
