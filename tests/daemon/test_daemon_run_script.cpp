// The README's first command, scripts/run.sh, as an operator runs it (with the suite's build, so
// without installing and building again): it serves the UI on the simulated bench, prints the
// address and a one-time operator token, answers GET /api/health without authentication, and
// stops cleanly on Ctrl-C.
#include <signal.h>
#include <stdlib.h>

#include <filesystem>
#include <regex>
#include <string>

#include <gtest/gtest.h>

#include "daemon_fixture.hpp"
#include "subprocess.hpp"
#include "tests/test_paths.hpp"

using namespace imucal;
using namespace imucal::daemontest;

TEST(RunScript, ServesTheUiAndHealthOnTheSimulatedBenchAndStopsOnCtrlC) {
  const std::string dir = scratch_dir("run-script");
  ::setenv("IMUCAL_RUN_PREBUILT", std::filesystem::path(imucaltest::program("imucald")).parent_path().c_str(), 1);
  Child child = spawn_child({"/bin/bash", imucaltest::source_dir() + "/scripts/run.sh", "--listen", "127.0.0.1:0", "--data-dir",
                             dir + "/data"},
                            dir + "/stderr.log");
  ::unsetenv("IMUCAL_RUN_PREBUILT");
  ASSERT_GT(child.pid, 0);
  const std::string out =
      read_stdout_until(child, [](const std::string& t) { return t.find("use it as") != std::string::npos; }, 60.0);
  std::smatch m;
  ASSERT_TRUE(std::regex_search(out, m, std::regex("listening on http://127\\.0\\.0\\.1:(\\d+)"))) << out;
  const auto port = static_cast<std::uint16_t>(std::stoi(m[1]));
  ASSERT_TRUE(std::regex_search(out, m, std::regex("\n  ([0-9a-f]{32,})\n"))) << "the one-time token: " << out;
  const std::string token = m[1];

  // Health: no authentication, no details.
  const HttpResult health = http_request(port, "GET", "/api/health");
  EXPECT_EQ(health.status, 200) << health.body;
  EXPECT_EQ(health.json_body(), json({{"status", "ok"}})) << health.body;
  EXPECT_EQ(http_request(port, "POST", "/api/health").status, 405);
  // The UI, and the rest of the API only with the token.
  const HttpResult page = http_request(port, "GET", "/");
  EXPECT_EQ(page.status, 200);
  EXPECT_NE(page.body.find("<title>"), std::string::npos) << page.body.substr(0, 300);
  EXPECT_EQ(http_request(port, "GET", "/api/status").status, 401);
  const HttpResult status = http_request(port, "GET", "/api/status", "", {{"Authorization", "Bearer " + token}});
  EXPECT_EQ(status.status, 200) << status.body;
  EXPECT_EQ(status.json_body().value("devices", std::string()), "sim") << status.body;

  // Ctrl-C: the script exec'd imucald, so the signal reaches it; it stops in order, status 0.
  ::kill(child.pid, SIGINT);
  EXPECT_EQ(wait_exit(child.pid, 60.0), 0);
}

// A start that fails (its port in use) prints no token, so it must keep none: the next start
// generates one and prints it (issue 18, item 5).
TEST(RunScript, AStartThatFailsKeepsNoTokenItNeverPrinted) {
  const std::string dir = scratch_dir("failed-start");
  const int busy = ::socket(AF_INET, SOCK_STREAM, 0);
  ASSERT_GE(busy, 0);
  sockaddr_in addr{};
  addr.sin_family = AF_INET;
  addr.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  ASSERT_EQ(::bind(busy, reinterpret_cast<sockaddr*>(&addr), sizeof addr), 0);
  ASSERT_EQ(::listen(busy, 1), 0);
  socklen_t len = sizeof addr;
  ::getsockname(busy, reinterpret_cast<sockaddr*>(&addr), &len);
  const std::string port = std::to_string(ntohs(addr.sin_port));

  Child failed = spawn_child({imucaltest::program("imucald"), "--listen", "127.0.0.1:" + port, "--data-dir", dir + "/data"}, dir + "/stderr-1.log");
  const std::string said = read_stdout_until(failed, [](const std::string&) { return false; }, 30.0);
  EXPECT_NE(wait_exit(failed.pid, 30.0), 0);
  EXPECT_EQ(said.find("use it as"), std::string::npos) << said;
  EXPECT_FALSE(std::filesystem::exists(dir + "/data/operator-token")) << "a token nobody was shown";
  ::close(busy);

  Child ok = spawn_child({imucaltest::program("imucald"), "--listen", "127.0.0.1:0", "--data-dir", dir + "/data"}, dir + "/stderr-2.log");
  const std::string shown =
      read_stdout_until(ok, [](const std::string& t) { return t.find("use it as") != std::string::npos; }, 60.0);
  EXPECT_NE(shown.find("generated a one-time operator token"), std::string::npos) << shown;
  EXPECT_TRUE(std::filesystem::exists(dir + "/data/operator-token"));
  ::kill(ok.pid, SIGTERM);
  EXPECT_EQ(wait_exit(ok.pid, 60.0), 0);
}
