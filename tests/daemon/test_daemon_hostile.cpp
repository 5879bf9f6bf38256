// What issue 33's probe of the API found, each as a test: a campaign names its truth (and models,
// chamber profiles) by name or inline, never by a path on the daemon's machine; malformed input of
// every kind is a 4xx naming the problem; a change the browser's cookie signs must come from
// imucald's own pages (the WebSocket too); and what one client can claim is bounded (connections,
// analysis jobs).
#include <sys/stat.h>

#include <atomic>
#include <filesystem>
#include <fstream>

#include <boost/asio/connect.hpp>
#include <boost/asio/ip/tcp.hpp>
#include <boost/beast/core.hpp>
#include <boost/beast/http.hpp>
#include <boost/beast/websocket.hpp>
#include <gtest/gtest.h>

#include "core/units.hpp"
#include "core/imu_model.hpp"
#include "daemon/analysis/analysis_jobs.hpp"
#include "service_fixture.hpp"
#include "tests/test_paths.hpp"

using namespace imucal;
using namespace imucal::daemontest;

namespace {

// A 4xx whose body is a JSON object with a non-empty "error" (what every refusal must be).
::testing::AssertionResult refused(const daemon::HttpReply& r, int status, const std::string& part = "") {
  json body;
  try {
    body = json::parse(r.body);
  } catch (const std::exception&) {
    return ::testing::AssertionFailure() << "status " << r.status << ", body not JSON: " << r.body.substr(0, 300);
  }
  if (r.status != status) return ::testing::AssertionFailure() << "status " << r.status << " (want " << status << "): " << r.body.substr(0, 500);
  const std::string error = body.is_object() ? body.value("error", std::string()) : std::string();
  if (error.empty()) return ::testing::AssertionFailure() << "no error: " << r.body.substr(0, 300);
  if (!part.empty() && error.find(part) == std::string::npos && r.body.find(part) == std::string::npos)
    return ::testing::AssertionFailure() << "'" << part << "' not in: " << r.body.substr(0, 500);
  return ::testing::AssertionSuccess();
}

const char* kModelText = R"({"format": "imucal-imu-model/1", "frame": "instrument", "gyro": {"bias_dph": [0.5, 0, 0]}})";

}  // namespace

// The truths folder: its models by name, read once; a path, a FIFO or a device never read.
TEST(Campaign, ModelsAreNamedNeverPaths) {
  const std::string dir = scratch_dir("truths");
  daemon::DaemonConfig config;
  config.data_dir = dir;
  std::filesystem::create_directories(dir + "/truths");
  std::ofstream(dir + "/truths/nav.json") << kModelText;
  std::ofstream(dir + "/truths/broken.json") << "{";
  ASSERT_EQ(::mkfifo((dir + "/truths/fifo.json").c_str(), 0600), 0);  // would block a reader
  daemon::resolve_named_models(config);
  EXPECT_EQ(config.named_models.size(), 2u) << "the built-in nav-grade and nav: the FIFO and the broken file are skipped";
  // The built-in realistic truth (issue 36, item 3): examples/truth-nav-grade.json, noise included.
  const auto builtin = daemon::check_campaign(json{{"name", "x"}, {"program", "direct-short"}, {"truth", "nav-grade"}}, config);
  ASSERT_TRUE(builtin.spec) << builtin.problems.front();
  EXPECT_EQ(builtin.spec->truth.gyro.bias_radps, read_imu_model_file(imucaltest::source_dir() + "/examples/truth-nav-grade.json").gyro.bias_radps);
  EXPECT_GT(builtin.spec->truth.gyro.noise.arw_rad_rts, 0.0);
  EXPECT_GT(builtin.spec->truth.accel.noise.vrw_mps_rts, 0.0);
  const auto truths = daemon::named_truths(config);
  ASSERT_EQ(truths.size(), 3u);
  EXPECT_EQ(truths[0].name, "ideal");
  EXPECT_EQ(truths[1].name, "nav");
  EXPECT_EQ(truths[2].name, "nav-grade");
  EXPECT_TRUE(truths[2].builtin);
  EXPECT_FALSE(truths[1].builtin);
  EXPECT_NE(truths[2].description.find("navigation-grade"), std::string::npos) << truths[2].description;
  // The API's default stays ideal (many tests rely on it); the builder sends nav-grade by name.
  EXPECT_EQ(config.sim.truth, "ideal");
  const auto named = daemon::check_campaign(json{{"name", "x"}, {"program", "direct-short"}, {"truth", "nav"}}, config);
  ASSERT_TRUE(named.spec) << named.problems.front();
  EXPECT_NEAR(named.spec->truth.gyro.bias_radps.x(), 0.5 * units::kDphToRadps, 1e-15);
  EXPECT_TRUE(named.spec->normalized.at("truth").is_object()) << "stored inline";

  for (const std::string& path : std::vector<std::string>{"/dev/zero", "/etc/shadow", "../truths/nav.json", "./nav", dir + "/truths/nav.json"}) {
    const auto c = daemon::check_campaign(json{{"name", "x"}, {"program", "direct-short"}, {"truth", path}}, config);
    EXPECT_FALSE(c.spec) << path;
    EXPECT_TRUE(c.malformed) << path;
    ASSERT_FALSE(c.problems.empty());
    EXPECT_NE(c.problems.front().find("campaign.truth: a path is not accepted"), std::string::npos) << c.problems.front();
  }
  const auto unknown = daemon::check_campaign(json{{"name", "x"}, {"program", "direct-short"}, {"truth", "nva"}}, config);
  EXPECT_FALSE(unknown.malformed);
  ASSERT_FALSE(unknown.problems.empty());
  EXPECT_NE(unknown.problems.front().find("no model named \"nva\" (known: ideal, nav"), std::string::npos) << unknown.problems.front();
  // The start model and a chamber profile the same way.
  const auto model = daemon::check_campaign(
      json{{"name", "x"}, {"program", "direct-short"}, {"model", "/etc/passwd"}}, config);
  EXPECT_TRUE(model.malformed);
  const auto profile = daemon::check_campaign(
      json{{"name", "x"}, {"program", "direct-short"}, {"chamber", {{"profile", "/dev/zero"}}}}, config);
  EXPECT_TRUE(profile.malformed);
  ASSERT_FALSE(profile.problems.empty());
  EXPECT_NE(profile.problems.front().find("a path is not accepted"), std::string::npos) << profile.problems.front();
  // `imucal campaign run FILE`: its author's own machine, paths allowed.
  config.campaign_file_paths = true;
  const auto local = daemon::check_campaign(
      json{{"name", "x"}, {"program", "direct-short"}, {"truth", dir + "/truths/nav.json"}}, config);
  EXPECT_TRUE(local.spec);
}

// The probe's examples, and the classes they stand for, through the API in process.
TEST(Hostile, MalformedInputIsA4xxNamingTheProblem) {
  LocalDaemon d("malformed");
  // Invalid UTF-8 in the URL and the body; numbers no double holds; wrong top-level types.
  EXPECT_TRUE(refused(d.call("GET", "/api/campaigns/%ff"), 400, "UTF-8"));
  EXPECT_TRUE(refused(d.call("GET", "/api/imus/%c3%28"), 400, "UTF-8"));
  EXPECT_TRUE(refused(d.call("GET", "/api/alarms?campaign=%ed%a0%80"), 400, "UTF-8"));  // a surrogate
  EXPECT_TRUE(refused(d.call("POST", "/api/campaigns", "{\"name\": \"\xff\", \"program\": \"direct-short\"}"), 400));
  EXPECT_TRUE(refused(d.call("POST", "/api/campaigns/validate", R"({"name": "\udcff", "program": "direct-short"})"), 400));
  EXPECT_TRUE(refused(d.call("POST", "/api/campaigns", R"({"name": "x", "program": "direct-short", "rate_hz": 1e999})"), 400,
                      "malformed JSON"));
  EXPECT_TRUE(refused(d.call("POST", "/api/campaigns/plan", R"({"name": "x", "program": "direct-short", "plan": {"rate_hz": -1e999}})"),
                      400));
  EXPECT_TRUE(refused(d.call("PUT", "/api/limits", "[]"), 400, "JSON object"));
  EXPECT_TRUE(refused(d.call("PUT", "/api/limits", "7"), 400));
  EXPECT_TRUE(refused(d.call("POST", "/api/campaigns/validate", "[]"), 400));
  EXPECT_TRUE(refused(d.call("POST", "/api/login", "[]"), 400));
  EXPECT_TRUE(refused(d.call("POST", "/api/campaigns/1/accept", "\"text\""), 400));
  // A truth named by path: refused at once (no read: /dev/zero would never end, a FIFO block).
  for (const char* path : {"/dev/zero", "/etc/shadow", "/proc/self/environ"}) {
    const auto r = d.call("POST", "/api/campaigns/validate",
                          json{{"name", "x"}, {"program", "direct-short"}, {"truth", path}}.dump(), kViewerToken);
    EXPECT_TRUE(refused(r, 400, "a path is not accepted")) << path;
    EXPECT_EQ(r.body.find("last read"), std::string::npos) << r.body;
    EXPECT_TRUE(refused(d.call("POST", "/api/campaigns", json{{"name", "x"}, {"program", "direct-short"}, {"truth", path}}.dump()),
                        400, "a path is not accepted"));
  }

  // A queued campaign's recording and analyses: 409 (it will have them), not 404. A running one
  // ahead of it holds the bench (real time: it stays running while the test looks).
  const auto running = d.post_campaign({{"name", "ahead"}, {"program", "noise"}, {"rate_hz", 10}, {"time_scale", 1}});
  const auto queued = d.post_campaign({{"name", "behind"}, {"program", "direct-short"}, {"rate_hz", 10}, {"time_scale", 0}});
  ASSERT_EQ(d.command(running, "start"), 200);
  d.wait_state(running, "running");
  ASSERT_EQ(d.command(queued, "start"), 200);
  ASSERT_EQ(d.campaign(queued).at("state"), "queued");
  const std::string q = "/api/campaigns/" + std::to_string(queued);
  EXPECT_TRUE(refused(d.call("GET", q + "/recording"), 409, "queued"));
  for (const char* what : {"/allan", "/thermal", "/evaluation"}) EXPECT_TRUE(refused(d.call("GET", q + what), 409, "queued")) << what;
  // The series of a recording: a range of program seconds, from < to, in the time base's reach.
  const std::string r = "/api/campaigns/" + std::to_string(running) + "/series";
  d.wait_for(running, [](const json& c) { return c.value("frames", 0) > 10; });
  EXPECT_EQ(d.call("GET", r).status, 200);
  EXPECT_TRUE(refused(d.call("GET", r + "?to_s=1e10"), 400, "from 0 to"));
  EXPECT_TRUE(refused(d.call("GET", r + "?from_s=1e300"), 400));
  EXPECT_TRUE(refused(d.call("GET", r + "?from_s=20&to_s=10"), 400, "must be after from_s"));
  EXPECT_TRUE(refused(d.call("GET", r + "?from_s=nan"), 400));
  EXPECT_TRUE(refused(d.call("GET", r + "?points=0"), 400));
  EXPECT_EQ(d.command(queued, "abort"), 200);
  EXPECT_EQ(d.command(running, "abort"), 200);
  d.wait_final(running);
}

// A browser's WebSocket from another site's page carries the cookie; it is refused. A token in
// the URL is no ambient credential: a script that has it may connect from anywhere.
TEST(Hostile, CrossOriginWebSocketWithACookieIsRefused) {
  namespace beast = boost::beast;
  namespace websocket = beast::websocket;
  namespace net = boost::asio;
  using tcp = net::ip::tcp;
  LocalDaemon d("ws-origin", true);
  const std::uint16_t port = d.service->port();
  const auto login = http_request(port, "POST", "/api/login", json{{"token", kViewerToken}}.dump());
  ASSERT_EQ(login.status, 200);
  const std::string cookie = login.session_cookie();
  const auto open = [&](const std::string& origin, const std::string& target, bool with_cookie) {
    net::io_context ioc;
    websocket::stream<tcp::socket> ws(ioc);
    ws.next_layer().connect(tcp::endpoint(net::ip::make_address("127.0.0.1"), port));
    ws.set_option(websocket::stream_base::decorator([&](websocket::request_type& req) {
      if (with_cookie) req.set(beast::http::field::cookie, cookie);
      if (!origin.empty()) req.set(beast::http::field::origin, origin);
    }));
    websocket::response_type res;
    beast::error_code ec;
    ws.handshake(res, "127.0.0.1", target, ec);
    return static_cast<int>(res.result_int());
  };
  EXPECT_EQ(open("http://evil.example", "/api/live", true), 403);
  EXPECT_EQ(open("null", "/api/live", true), 403);
  EXPECT_EQ(open("http://127.0.0.1", "/api/live", true), 101);
  EXPECT_EQ(open("", "/api/live", true), 101) << "no Origin: not a browser's cross-site request";
  EXPECT_EQ(open("http://evil.example", std::string("/api/live?token=") + kViewerToken, false), 101);
}

// One client's open connections are bounded; the others' are not touched by it, and a closed
// connection gives its slot back.
TEST(Hostile, ConnectionsPerClientAreBounded) {
  LocalDaemon d("connections", true, [](daemon::DaemonConfig& c) { c.http.max_connections_per_client = 4; });
  const std::uint16_t port = d.service->port();
  std::vector<int> idle;
  const auto connect = [&] {
    const int fd = ::socket(AF_INET, SOCK_STREAM, 0);
    sockaddr_in addr{};
    addr.sin_family = AF_INET;
    addr.sin_port = htons(port);
    addr.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
    EXPECT_EQ(::connect(fd, reinterpret_cast<sockaddr*>(&addr), sizeof addr), 0);
    return fd;
  };
  for (int i = 0; i < 4; ++i) idle.push_back(connect());
  // The server counts a connection once it has accepted it: wait until the fifth is refused.
  HttpResult fifth;
  for (int i = 0; i < 200 && fifth.status != 429; ++i) {
    fifth = http_request(port, "GET", "/api/health");
    if (fifth.status != 429) std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }
  EXPECT_EQ(fifth.status, 429);
  EXPECT_NE(fifth.json_body().value("error", std::string()).find("too many connections"), std::string::npos) << fifth.body;
  for (const int fd : idle) ::close(fd);
  HttpResult again;
  for (int i = 0; i < 200 && again.status != 200; ++i) {
    again = http_request(port, "GET", "/api/health");
    if (again.status != 200) std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }
  EXPECT_EQ(again.status, 200) << "the slots came back";
}

// Analyses waiting or computing at once are bounded: one more is 429, a join is not one more.
TEST(Hostile, AnalysisJobsAreBounded) {
  std::atomic<bool> release{false};
  daemon::AnalysisJobs jobs(1, 10, {}, 2);
  const auto blocking = [&](const daemon::AnalysisJobs::Progress&) -> std::pair<int, json> {
    while (!release) std::this_thread::sleep_for(std::chrono::milliseconds(2));
    return {200, json{{"ok", true}}};
  };
  const auto key = [](std::int64_t id) {
    daemon::AnalysisJobs::Key k;
    k.campaign = id;
    k.analysis = "allan";
    k.state = "done";
    return k;
  };
  EXPECT_FALSE(jobs.request(key(1), blocking).ready);
  EXPECT_FALSE(jobs.request(key(2), blocking).ready);
  EXPECT_FALSE(jobs.request(key(1), blocking).ready) << "joins the job under way";
  const auto third = jobs.request(key(3), blocking);
  EXPECT_TRUE(third.ready);
  EXPECT_EQ(third.status, 429);
  EXPECT_NE(third.body.find("too many analyses"), std::string::npos) << third.body;
  release = true;
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(60);
  while (!jobs.request(key(2), blocking).ready && std::chrono::steady_clock::now() < deadline)
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
  EXPECT_EQ(jobs.request(key(3), blocking).ready, false) << "room again: it starts";
}

// Behind a reverse proxy the configuration trusts, sign-in throttling counts the client the
// proxy names in X-Forwarded-For (issue 33), not the proxy: one guesser behind nginx does not lock
// out the lab. Without the setting the header is ignored, so a client cannot dodge its own
// lock-out by writing one.
TEST(Hostile, SignInThrottlingCountsTheClientBehindATrustedProxy) {
  const json wrong = {{"user", "viewer"}, {"password", "a wrong guess"}};
  const json right = {{"user", "viewer"}, {"password", "viewer-password"}};
  auto login = [](std::uint16_t port, const json& body, const std::string& forwarded_for) {
    std::map<std::string, std::string> headers = {{"Content-Type", "application/json"}};
    if (!forwarded_for.empty()) headers["X-Forwarded-For"] = forwarded_for;
    return http_request(port, "POST", "/api/login", body.dump(), headers).status;
  };
  {
    LocalDaemon d("proxy-trusted", true, [](daemon::DaemonConfig& c) { c.http.trusted_proxies = {"127.0.0.1"}; });
    const std::uint16_t port = d.service->port();
    for (int i = 0; i < 5; ++i) EXPECT_EQ(login(port, wrong, "10.0.0.1"), 401);
    EXPECT_EQ(login(port, right, "10.0.0.1"), 429);
    // Another client behind the same proxy; and one whose own header claims to be someone else
    // (the proxy appends the address it saw: the rightmost untrusted entry counts).
    EXPECT_EQ(login(port, right, "10.0.0.2"), 200);
    EXPECT_EQ(login(port, right, "10.0.0.2, 10.0.0.1"), 429);
  }
  {
    LocalDaemon d("proxy-untrusted", true);
    const std::uint16_t port = d.service->port();
    for (int i = 0; i < 5; ++i) EXPECT_EQ(login(port, wrong, "10.0.0.1"), 401);
    EXPECT_EQ(login(port, right, "10.0.0.9"), 429);
  }
}
