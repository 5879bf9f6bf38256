// imucald over HTTP on an ephemeral port (in-process): the acceptance end-to-end run (post a
// campaign, start, pause, resume, finish, fetch the model), authentication and roles, every kind
// of bad input answered with a clear JSON error, static files, and the live WebSocket.
#include <filesystem>
#include <fstream>

#include <boost/asio/connect.hpp>
#include <boost/asio/ip/tcp.hpp>
#include <boost/beast/core.hpp>
#include <boost/beast/http.hpp>
#include <boost/beast/websocket.hpp>
#include <gtest/gtest.h>

#include "service_fixture.hpp"

using namespace imucal;
using namespace imucal::daemontest;

namespace {

std::string error_of(const HttpResult& r) { return r.json_body().value("error", std::string("<no error>")); }

}  // namespace

TEST(Http, EndToEndPostStartPauseResumeFinishModel) {
  LocalDaemon d("e2e", true);
  const Client op{d.service->port(), kOperatorToken};
  ASSERT_NE(op.port, 0);
  const json programs = op.get_json("/api/programs");
  // Every built-in program and the campaign `full`, each with the estimators a campaign of it runs
  // by default (the builder offers those).
  std::map<std::string, json> by_name;
  for (const auto& p : programs.at("programs")) by_name[p.at("name").get<std::string>()] = p;
  ASSERT_TRUE(by_name.count("direct-short"));
  ASSERT_TRUE(by_name.count("full")) << programs.dump().substr(0, 500);
  EXPECT_EQ(by_name.at("full").at("estimators"), json({"direct", "lever-arm", "stage3"}));
  // Its four programs, with a move to each one's start pose inserted between them.
  const double parts_s = by_name.at("direct").at("duration_s").get<double>() +
                         by_name.at("lever-arm").at("duration_s").get<double>() +
                         by_name.at("navigation").at("duration_s").get<double>() +
                         by_name.at("evaluate").at("duration_s").get<double>();
  EXPECT_GE(by_name.at("full").at("duration_s").get<double>(), parts_s);
  EXPECT_LT(by_name.at("full").at("duration_s").get<double>(), parts_s + 60.0);
  EXPECT_EQ(by_name.at("navigation").at("estimators"), json({"stage3"}));
  EXPECT_EQ(by_name.at("direct").at("estimators"), json({"direct"}));
  EXPECT_EQ(by_name.at("rate-steps").at("estimators"), json({"rate-steps"}));
  EXPECT_EQ(by_name.at("rate-steps-short").at("estimators"), json({"rate-steps"}));
  EXPECT_EQ(by_name.at("tumble").at("estimators"), json({"tumble"}));
  EXPECT_EQ(by_name.at("tumble-short").at("estimators"), json({"tumble"}));
  EXPECT_EQ(by_name.at("warm-up").at("estimators"), json({"warm-up"}));
  EXPECT_EQ(by_name.at("warm-up-short").at("estimators"), json({"warm-up"}));
  EXPECT_EQ(by_name.at("repeatability").at("estimators"), json({"repeatability"}));
  EXPECT_EQ(by_name.at("repeatability-short").at("estimators"), json({"repeatability"}));

  const auto posted = op.post("/api/campaigns", R"({"name": "e2e", "program": "direct-short", "rate_hz": 100,
                                                    "time_scale": 100})");
  ASSERT_EQ(posted.status, 201) << posted.body;
  const auto id = posted.json_body().at("id").get<std::int64_t>();
  EXPECT_EQ(posted.headers.at("location"), "/api/campaigns/" + std::to_string(id));
  EXPECT_EQ(op.get_json("/api/campaigns/" + std::to_string(id)).at("state"), "created");

  ASSERT_EQ(op.post("/api/campaigns/" + std::to_string(id) + "/start").status, 200);
  op.wait_for(id, [](const json& c) { return c.at("state") == "running" && c.at("program_time_s").get<double>() > 40.0; });
  const auto status = op.get_json("/api/status");
  EXPECT_EQ(status.at("active").at("id"), id);

  const auto pause = op.post("/api/campaigns/" + std::to_string(id) + "/pause", R"({"reason": "coffee"})");
  ASSERT_EQ(pause.status, 200) << pause.body;
  EXPECT_EQ(pause.json_body().at("state"), "pausing");
  op.wait_state(id, "paused");
  const auto resume = op.post("/api/campaigns/" + std::to_string(id) + "/resume");
  ASSERT_EQ(resume.status, 200) << resume.body;
  EXPECT_EQ(resume.json_body().at("state"), "running");
  const json done = op.wait_state(id, "done", 90);
  EXPECT_TRUE(has_transition(done, "paused", "running"));
  bool reason_kept = false;
  for (const auto& t : done.at("transitions"))
    reason_kept = reason_kept || t.at("reason").get<std::string>().find("coffee") != std::string::npos;
  EXPECT_TRUE(reason_kept);

  const auto model = op.get("/api/campaigns/" + std::to_string(id) + "/model");
  ASSERT_EQ(model.status, 200);
  EXPECT_EQ(model.json_body().at("format"), "imucal-imu-model/1");
  EXPECT_TRUE(model.json_body().contains("sigma"));
  const auto list = op.get_json("/api/campaigns");
  ASSERT_EQ(list.at("campaigns").size(), 1u);
  EXPECT_EQ(list.at("campaigns")[0].at("state"), "done");
  EXPECT_TRUE(list.at("campaigns")[0].at("has_model").get<bool>());
  expect_same_frames(run_frames(d.run_path(done)), reference_frames(done.at("spec"), d.config));
}

TEST(Http, AuthenticationAndRoles) {
  LocalDaemon d("auth", true);
  const std::uint16_t port = d.service->port();
  const Client anon{port, ""}, viewer{port, kViewerToken}, op{port, kOperatorToken}, wrong{port, "not-a-token-at-all"};

  const auto r = anon.get("/api/status");
  EXPECT_EQ(r.status, 401);
  EXPECT_EQ(error_of(r), "authentication required");
  EXPECT_EQ(r.headers.count("www-authenticate"), 1u);
  EXPECT_EQ(wrong.get("/api/status").status, 401);
  EXPECT_EQ(viewer.get("/api/status").status, 200);
  EXPECT_EQ(viewer.get_json("/api/me").at("role"), "viewer");

  // A viewer reads everything and changes nothing.
  const auto vpost = viewer.post("/api/campaigns", R"({"name": "v", "program": "direct-short"})");
  EXPECT_EQ(vpost.status, 403);
  EXPECT_EQ(error_of(vpost), "operator role required");
  const auto id = op.post("/api/campaigns", R"({"name": "o", "program": "direct-short"})").json_body().at("id").get<int>();
  EXPECT_EQ(viewer.post("/api/campaigns/" + std::to_string(id) + "/start").status, 403);
  EXPECT_EQ(anon.post("/api/campaigns/" + std::to_string(id) + "/start").status, 401);
  EXPECT_EQ(viewer.get_json("/api/campaigns/" + std::to_string(id)).at("state"), "created");
  EXPECT_EQ(viewer.post("/api/campaigns/validate", R"({"name": "v", "program": "direct-short"})").status, 200);

  // Browser sign-in: a session cookie.
  const auto bad = http_request(port, "POST", "/api/login", R"({"user": "viewer", "password": "nope"})");
  EXPECT_EQ(bad.status, 401);
  const auto login = http_request(port, "POST", "/api/login", R"({"user": "viewer", "password": "viewer-password"})");
  ASSERT_EQ(login.status, 200) << login.body;
  const std::string set_cookie = login.headers.at("set-cookie");
  EXPECT_NE(set_cookie.find("HttpOnly"), std::string::npos);
  EXPECT_NE(set_cookie.find("SameSite=Strict"), std::string::npos);
  const std::string cookie = login.session_cookie();
  const auto me = http_request(port, "GET", "/api/me", "", {{"Cookie", cookie}});
  ASSERT_EQ(me.status, 200);
  EXPECT_EQ(me.json_body().at("via"), "session");
  EXPECT_EQ(http_request(port, "POST", "/api/campaigns/" + std::to_string(id) + "/start", "",
                         {{"Cookie", cookie}, {"Content-Type", "application/json"}})
                .status,
            403);
  // The generated or configured token signs an operator in.
  const auto op_login = http_request(port, "POST", "/api/login", json{{"token", kOperatorToken}}.dump());
  ASSERT_EQ(op_login.status, 200);
  EXPECT_EQ(op_login.json_body().at("role"), "operator");
  const std::string op_cookie = op_login.session_cookie();
  // A change the cookie signs must come from imucald's own pages (issue 33): a form's type, or
  // another site's Origin, is refused before anything happens; a token is no ambient credential.
  const std::string start = "/api/campaigns/" + std::to_string(id) + "/start";
  const auto form = http_request(port, "POST", start, "", {{"Cookie", op_cookie}, {"Content-Type", "application/x-www-form-urlencoded"}});
  EXPECT_EQ(form.status, 415);
  EXPECT_NE(error_of(form).find("Content-Type: application/json"), std::string::npos) << form.body;
  EXPECT_EQ(http_request(port, "POST", start, "", {{"Cookie", op_cookie}}).status, 415) << "no type at all";
  const auto foreign = http_request(port, "POST", start, "{}",
                                    {{"Cookie", op_cookie}, {"Content-Type", "application/json"}, {"Origin", "http://evil.example"}});
  EXPECT_EQ(foreign.status, 403);
  EXPECT_NE(error_of(foreign).find("cross-origin"), std::string::npos) << foreign.body;
  EXPECT_EQ(http_request(port, "POST", start, "{}",
                         {{"Cookie", op_cookie}, {"Content-Type", "application/json"}, {"Origin", "null"}})
                .status,
            403);
  EXPECT_EQ(op.get_json("/api/campaigns/" + std::to_string(id)).at("state"), "created") << "nothing started";
  // The same-origin page (Origin is this Host) may; a bearer token from anywhere may.
  EXPECT_EQ(http_request(port, "POST", "/api/campaigns/" + std::to_string(id) + "/abort", "",
                         {{"Cookie", op_cookie}, {"Content-Type", "application/json"}, {"Origin", "http://127.0.0.1"}})
                .status,
            200);
  EXPECT_EQ(http_request(port, "POST", "/api/campaigns/validate", R"({"name": "x", "program": "direct-short"})",
                         {{"Authorization", std::string("Bearer ") + kOperatorToken}, {"Origin", "http://evil.example"}})
                .status,
            200);
  EXPECT_EQ(http_request(port, "POST", "/api/logout", "", {{"Cookie", op_cookie}, {"Content-Type", "application/json"}}).status, 200);
  EXPECT_EQ(http_request(port, "GET", "/api/me", "", {{"Cookie", op_cookie}}).status, 401);
}

TEST(Http, BadInputGetsAClearErrorAndChangesNothing) {
  LocalDaemon d("bad-input", true, [](daemon::DaemonConfig& c) {
    c.http.body_limit_bytes = 4096;
    c.table_limits.axis[0].rate_dps = 25.0;  // the built-in programs' 30 deg/s runs are too fast here
  });
  const Client op{d.service->port(), kOperatorToken};

  const auto malformed = op.post("/api/campaigns", R"({"name": "x", "program": )");
  EXPECT_EQ(malformed.status, 400);
  EXPECT_NE(error_of(malformed).find("malformed JSON"), std::string::npos) << malformed.body;

  const auto unknown = op.post("/api/campaigns", R"({"name": "x", "program": "direct", "speed": 3})");
  EXPECT_EQ(unknown.status, 400);
  EXPECT_NE(error_of(unknown).find("unknown key \"speed\""), std::string::npos) << unknown.body;

  const auto wrong_type = op.post("/api/campaigns", R"(["direct"])");
  EXPECT_EQ(wrong_type.status, 400);

  const auto limits = op.post("/api/campaigns", R"({"name": "x", "program": "direct-short", "chamber": {"setpoint_C": 300}})");
  EXPECT_EQ(limits.status, 422);
  EXPECT_EQ(error_of(limits), "campaign is invalid");
  const auto problems = limits.json_body().at("problems");
  EXPECT_GE(problems.size(), 2u) << limits.body;  // the table rate and the chamber, both listed
  EXPECT_NE(limits.body.find("exceeds the limit 25"), std::string::npos) << limits.body;
  EXPECT_NE(limits.body.find("300 °C is outside"), std::string::npos) << limits.body;

  const auto valid = op.post("/api/campaigns/validate", R"({"name": "x", "program": "direct-short"})");
  EXPECT_EQ(valid.status, 200);
  EXPECT_FALSE(valid.json_body().at("valid").get<bool>());

  const std::string big = R"({"name": ")" + std::string(10000, 'x') + R"(", "program": "noise"})";
  const auto too_big = op.post("/api/campaigns", big);
  EXPECT_EQ(too_big.status, 413);
  EXPECT_NE(error_of(too_big).find("larger than 4096"), std::string::npos);

  const auto form = http_request(op.port, "POST", "/api/campaigns", "name=x",
                                 {{"Authorization", std::string("Bearer ") + kOperatorToken},
                                  {"Content-Type", "application/x-www-form-urlencoded"}});
  EXPECT_EQ(form.status, 415);

  // Nothing of the above was stored.
  EXPECT_EQ(op.get_json("/api/campaigns").at("campaigns").size(), 0u);

  const auto ok = op.post("/api/campaigns", R"({"name": "noise", "program": "noise", "estimators": ["navigation"],
                                                "time_scale": 0})");
  ASSERT_EQ(ok.status, 201) << ok.body;
  const auto id = std::to_string(ok.json_body().at("id").get<int>());
  const auto early = op.post("/api/campaigns/" + id + "/resume");
  EXPECT_EQ(early.status, 409);
  EXPECT_EQ(early.json_body().at("state"), "created");
  EXPECT_EQ(op.post("/api/campaigns/" + id + "/frobnicate").status, 404);
  const auto get_start = op.get("/api/campaigns/" + id + "/start");
  EXPECT_EQ(get_start.status, 405);
  EXPECT_EQ(get_start.headers.at("allow"), "POST");
  EXPECT_EQ(op.get("/api/campaigns/999").status, 404);
  EXPECT_EQ(op.get("/api/campaigns/abc").status, 404);
  EXPECT_EQ(op.get("/api/campaigns/" + id + "/model").status, 404);
  EXPECT_EQ(op.get("/api/nothing").status, 404);
  EXPECT_EQ(op.get("/api/campaigns?limit=0").status, 400);
  EXPECT_EQ(op.post("/api/campaigns/" + id + "/start", R"({"why": 1})").status, 400);
  EXPECT_EQ(op.post("/api/campaigns/" + id + "/start").status, 200);
  const auto twice = op.post("/api/campaigns/" + id + "/start");
  EXPECT_EQ(twice.status, 409);
  EXPECT_NE(error_of(twice).find("already started"), std::string::npos);
  EXPECT_EQ(op.post("/api/campaigns/" + id + "/abort").status, 200);
  EXPECT_EQ(op.wait_for(std::stoll(id), [](const json& c) { return c.at("state") == "aborted"; }).at("state"), "aborted");
}

TEST(Http, StaticFilesWithTypesAndNoTraversal) {
  std::string web;
  LocalDaemon d("static", true, [&](daemon::DaemonConfig& c) {
    web = c.data_dir + "/../static-web-" + std::to_string(::getpid());
    std::filesystem::create_directories(web + "/css");
    std::ofstream(web + "/index.html") << "<!doctype html><title>imucal</title>";
    std::ofstream(web + "/css/site.css") << "body{}";
    c.http.web_dir = web;
  });
  const std::uint16_t port = d.service->port();
  const auto index = http_request(port, "GET", "/");
  ASSERT_EQ(index.status, 200);
  EXPECT_EQ(index.headers.at("content-type"), "text/html; charset=utf-8");
  EXPECT_EQ(index.headers.at("cache-control"), "no-cache");
  const auto css = http_request(port, "GET", "/css/site.css");
  ASSERT_EQ(css.status, 200);
  EXPECT_EQ(css.headers.at("content-type"), "text/css; charset=utf-8");
  EXPECT_EQ(http_request(port, "GET", "/css/site.css", "", {{"If-None-Match", css.headers.at("etag")}}).status, 304);
  for (const char* evil : {"/../imucald.db", "/%2e%2e/%2e%2e/etc/passwd", "/css/../../etc/passwd", "/.hidden"}) {
    const auto r = http_request(port, "GET", evil);
    EXPECT_TRUE(r.status == 404 || r.status == 400) << evil << ": " << r.status;
  }
  EXPECT_EQ(http_request(port, "POST", "/index.html", "x").status, 405);
}

TEST(Http, LiveWebSocketSendsTelemetryToViewersOnly) {
  namespace beast = boost::beast;
  namespace websocket = beast::websocket;
  namespace net = boost::asio;
  using tcp = net::ip::tcp;
  LocalDaemon d("live", true);
  const std::uint16_t port = d.service->port();
  const Client op{port, kOperatorToken};
  const auto id = op.post("/api/campaigns", R"({"name": "live", "program": "direct-short", "time_scale": 100})")
                      .json_body()
                      .at("id")
                      .get<std::int64_t>();
  ASSERT_EQ(op.post("/api/campaigns/" + std::to_string(id) + "/start").status, 200);

  net::io_context ioc;
  auto connect = [&](const std::string& token, const std::string& target) {
    auto ws = std::make_unique<websocket::stream<tcp::socket>>(ioc);
    ws->next_layer().connect(tcp::endpoint(net::ip::make_address("127.0.0.1"), port));
    ws->set_option(websocket::stream_base::decorator([token](websocket::request_type& req) {
      if (!token.empty()) req.set(beast::http::field::authorization, "Bearer " + token);
    }));
    ws->handshake("127.0.0.1", target);
    return ws;
  };
  EXPECT_THROW(connect("", "/api/live"), boost::system::system_error);
  EXPECT_THROW(connect("wrong-token-wrong-token", "/api/live"), boost::system::system_error);

  auto ws = connect(kViewerToken, "/api/live");
  beast::flat_buffer buffer;
  ws->read(buffer);
  const json hello = json::parse(beast::buffers_to_string(buffer.data()));
  EXPECT_EQ(hello.at("type"), "hello");
  EXPECT_EQ(hello.at("role"), "viewer");
  std::uint64_t last_seq = 0;
  int telemetry = 0, transitions = 0;
  bool saw_run = false;
  for (int i = 0; i < 60 && telemetry < 15; ++i) {
    buffer.consume(buffer.size());
    ws->read(buffer);
    const json m = json::parse(beast::buffers_to_string(buffer.data()));
    ASSERT_TRUE(m.contains("seq"));
    EXPECT_GT(m.at("seq").get<std::uint64_t>(), last_seq);
    last_seq = m.at("seq").get<std::uint64_t>();
    if (m.at("type") == "telemetry") {
      ++telemetry;
      for (const char* key : {"table", "chamber", "imu", "recorder", "estimators", "run"}) ASSERT_TRUE(m.contains(key)) << key;
      EXPECT_EQ(m.at("table").at("angle_deg").size(), 3u);
      if (m.at("run").is_object()) {
        saw_run = true;
        EXPECT_EQ(m.at("run").at("id"), id);
        EXPECT_TRUE(m.at("imu").contains("lost_frames"));
        EXPECT_TRUE(m.at("chamber").contains("setpoint_C"));
      }
    } else if (m.at("type") == "event" && m.at("kind") == "transition") {
      ++transitions;
    }
  }
  EXPECT_GE(telemetry, 15);
  EXPECT_TRUE(saw_run);
  // With the query token too (for scripts that cannot set headers).
  auto ws2 = connect("", std::string("/api/live?token=") + kViewerToken);
  buffer.consume(buffer.size());
  ws2->read(buffer);
  EXPECT_EQ(json::parse(beast::buffers_to_string(buffer.data())).at("type"), "hello");
  ASSERT_EQ(op.post("/api/campaigns/" + std::to_string(id) + "/abort").status, 200);
  // The transition reaches the live clients as an event.
  bool saw_abort = false;
  for (int i = 0; i < 200 && !saw_abort; ++i) {
    buffer.consume(buffer.size());
    ws->read(buffer);
    const json m = json::parse(beast::buffers_to_string(buffer.data()));
    saw_abort = m.at("type") == "event" && m.value("to", "") == "aborting";
  }
  EXPECT_TRUE(saw_abort);
  ws->close(websocket::close_code::normal);
  ws2->close(websocket::close_code::normal);
  (void)transitions;
}

TEST(Http, HeadGivesTheLengthOfTheGet) {
  std::string web;
  LocalDaemon d("head", true, [&](daemon::DaemonConfig& c) {
    web = c.data_dir + "/../head-web-" + std::to_string(::getpid());
    std::filesystem::create_directories(web);
    std::ofstream(web + "/index.html") << "<!doctype html><title>0123456789</title>";
    c.http.web_dir = web;
  });
  const auto head = http_request(d.service->port(), "HEAD", "/index.html");
  ASSERT_EQ(head.status, 200);
  EXPECT_EQ(head.headers.at("content-length"), "40");
  EXPECT_TRUE(head.body.empty());
  EXPECT_EQ(head.headers.at("etag").find('-', 1) != std::string::npos, true);
}

// The results beyond the model (docs/api.md): the recording bundle as a tar file, the Allan
// deviation, the Schuler test of the model variants, thermal plots refused with the reason, and
// the IMU serial.
TEST(Http, ResultsEndpointsServeTheRunsAnalyses) {
  LocalDaemon d("results", true);
  const Client op{d.service->port(), kOperatorToken};
  const auto id = op.post("/api/campaigns",
                          R"({"name": "results", "program": ["direct-short", "evaluate"], "rate_hz": 20, "time_scale": 0})")
                      .json_body()
                      .at("id")
                      .get<std::int64_t>();
  const std::string base = "/api/campaigns/" + std::to_string(id);
  EXPECT_EQ(op.get(base + "/recording").status, 404);  // never started
  ASSERT_EQ(op.post(base + "/start").status, 200);
  const json done = op.wait_state(id, "done", 120.0);
  ASSERT_EQ(done.at("state"), "done") << done.dump().substr(0, 2000);
  EXPECT_EQ(done.at("imu_serial").get<std::string>().rfind("SIM-", 0), 0u);  // the simulated IMU's serial

  // Written as a job: 202 with its progress, then the file.
  const auto started = op.get(base + "/recording");
  ASSERT_EQ(started.status, 202) << started.body.substr(0, 500);
  EXPECT_EQ(started.json_body().value("analysis", ""), "recording") << started.body;
  EXPECT_TRUE(started.json_body().contains("progress")) << started.body;
  const auto tar = op.get_computed(base + "/recording");
  ASSERT_EQ(tar.status, 200) << tar.body.substr(0, 500);
  EXPECT_EQ(tar.headers.at("content-type"), "application/x-tar");
  EXPECT_NE(tar.headers.at("content-disposition").find("attachment"), std::string::npos);
  ASSERT_GT(tar.body.size(), 2048u);
  EXPECT_EQ(tar.body.size() % 512, 0u);
  const std::string top = "campaign-" + std::to_string(id) + "-recording/";
  EXPECT_EQ(tar.body.compare(0, top.size(), top), 0);
  EXPECT_EQ(tar.body.compare(257, 5, "ustar"), 0);
  EXPECT_NE(tar.body.find(top + "frames.csv"), std::string::npos);
  EXPECT_NE(tar.body.find(top + "meta.json"), std::string::npos);
  EXPECT_NE(tar.body.find("imucal-recording/1"), std::string::npos);
  {
    // An archive another tool reads: GNU tar lists the bundle and extracts its meta.json.
    const std::string file = d.config.data_dir + "/recording.tar";
    std::ofstream(file, std::ios::binary) << tar.body;
    auto run = [](const std::string& command) {
      std::string out;
      if (FILE* p = ::popen(command.c_str(), "r")) {
        char buf[4096];
        for (std::size_t n; (n = std::fread(buf, 1, sizeof buf, p)) > 0;) out.append(buf, n);
        ::pclose(p);
      }
      return out;
    };
    const std::string listing = run("tar -tf '" + file + "'");
    EXPECT_NE(listing.find(top + "frames.csv\n"), std::string::npos) << listing;
    EXPECT_NE(listing.find(top + "meta.json\n"), std::string::npos) << listing;
    EXPECT_NE(run("tar -xOf '" + file + "' " + top + "meta.json").find("imucal-recording/1"), std::string::npos);
  }
  const auto head = http_request(d.service->port(), "HEAD", base + "/recording", "", op.auth());
  EXPECT_EQ(head.status, 200);
  EXPECT_EQ(head.headers.at("content-length"), std::to_string(tar.body.size()));
  EXPECT_TRUE(head.body.empty());

  // Computed as a job: the first request starts it (202, with its progress), a later one gets it.
  const auto first = op.get(base + "/allan");
  if (first.status == 202) {
    EXPECT_TRUE(first.json_body().contains("progress")) << first.body;
    EXPECT_EQ(first.headers.at("retry-after"), "1");
  } else {
    EXPECT_EQ(first.status, 200) << first.body.substr(0, 300);
  }
  const json allan = op.get_computed(base + "/allan").json_body();
  ASSERT_TRUE(allan.contains("gyro_x")) << allan.dump().substr(0, 500);
  EXPECT_GT(allan.at("gyro_x").at("tau_s").size(), 5u);
  EXPECT_EQ(allan.at("gyro_x").at("tau_s").size(), allan.at("gyro_x").at("adev").size());
  EXPECT_EQ(allan.at("gyro_x").at("unit"), "deg/h");
  EXPECT_EQ(allan.at("arw_deg_rth").size(), 3u);

  // What the run cannot give is a 200 saying so (no error in a browser's console, issue 36).
  const auto thermal = op.get_computed(base + "/thermal");
  EXPECT_EQ(thermal.status, 200);
  EXPECT_EQ(thermal.json_body().at("available"), false) << thermal.body;
  EXPECT_NE(thermal.json_body().at("reason").get<std::string>().find("not available for this run"), std::string::npos);
  EXPECT_NE(thermal.json_body().at("reason").get<std::string>().find("thermal"), std::string::npos);

  // The truths a campaign may name, for the builder: ideal, the built-in nav-grade; the API's
  // default stays ideal.
  const json campaign_limits = op.get("/api/status").json_body().at("limits").at("campaign");
  EXPECT_EQ(campaign_limits.at("default_truth"), "ideal");
  std::vector<std::string> truth_names;
  for (const auto& t : campaign_limits.at("truths")) truth_names.push_back(t.at("name").get<std::string>());
  EXPECT_EQ(truth_names, (std::vector<std::string>{"ideal", "nav-grade"}));

  // The model against the simulation's truth, in the model's frame (stage 1: the instrument
  // frame, nothing converted, nothing zero by definition).
  const auto cmp = op.get(base + "/truth");
  ASSERT_EQ(cmp.status, 200) << cmp.body.substr(0, 500);
  const json comparison = cmp.json_body();
  EXPECT_EQ(comparison.at("frame"), "instrument");
  EXPECT_EQ(comparison.at("truth_frame"), "instrument");
  EXPECT_EQ(comparison.at("converted"), false);
  EXPECT_TRUE(comparison.at("zero_by_definition").empty());
  EXPECT_EQ(comparison.at("truth").at("frame"), "instrument");
  ASSERT_GE(comparison.at("rows").size(), 27u);
  EXPECT_EQ(comparison.at("rows").at(0).at("key"), "gyro.bias_dph.x");

  const auto evaluation = op.get_computed(base + "/evaluation");
  ASSERT_EQ(evaluation.status, 200) << evaluation.body.substr(0, 500);
  const json variants = evaluation.json_body().at("variants");
  ASSERT_EQ(variants.size(), 3u);  // uncalibrated, this campaign's model, the truth
  EXPECT_EQ(variants[0].at("name"), "uncalibrated");
  EXPECT_EQ(variants[2].at("name"), "truth");
  for (const auto& v : variants) {
    ASSERT_GE(v.at("segments").size(), 4u);
    const json& seg = v.at("segments")[0];
    EXPECT_GT(seg.at("time_s").size(), 10u);
    EXPECT_EQ(seg.at("time_s").size(), seg.at("velocity_error_mps").size());
  }
  // A campaign never started has nothing to analyse; an unknown one is 404 too.
  const auto created = op.post("/api/campaigns", R"({"name": "idle", "program": "direct-short"})").json_body().at("id");
  EXPECT_EQ(op.get("/api/campaigns/" + created.dump() + "/allan").status, 404);
  EXPECT_EQ(op.get("/api/campaigns/999/evaluation").status, 404);
}

// A browser session's WebSocket is closed (code 4001) when the session ends.
TEST(Http, LiveWebSocketClosesWhenItsSessionEnds) {
  namespace beast = boost::beast;
  namespace websocket = beast::websocket;
  namespace net = boost::asio;
  using tcp = net::ip::tcp;
  LocalDaemon d("live-session", true);
  const std::uint16_t port = d.service->port();
  const auto login = http_request(port, "POST", "/api/login", json{{"token", kViewerToken}}.dump());
  ASSERT_EQ(login.status, 200);
  const std::string cookie = login.session_cookie();

  net::io_context ioc;
  websocket::stream<tcp::socket> ws(ioc);
  ws.next_layer().connect(tcp::endpoint(net::ip::make_address("127.0.0.1"), port));
  ws.set_option(websocket::stream_base::decorator(
      [cookie](websocket::request_type& req) { req.set(beast::http::field::cookie, cookie); }));
  ws.handshake("127.0.0.1", "/api/live");
  beast::flat_buffer buffer;
  ws.read(buffer);
  EXPECT_EQ(json::parse(beast::buffers_to_string(buffer.data())).at("type"), "hello");

  ASSERT_EQ(http_request(port, "POST", "/api/logout", "", {{"Cookie", cookie}, {"Content-Type", "application/json"}}).status, 200);
  beast::error_code ec;
  for (int i = 0; i < 100 && !ec; ++i) {
    buffer.consume(buffer.size());
    ws.read(buffer, ec);
  }
  EXPECT_TRUE(ec == websocket::error::closed) << ec.message();
  EXPECT_EQ(static_cast<int>(ws.reason().code), 4001);
  EXPECT_NE(std::string(ws.reason().reason.c_str()).find("session ended"), std::string::npos);
}

// The builder's prediction (issue 16): POST /api/campaigns/plan answers, for a viewer too, with the
// 1-sigma each stage will report, as a job (202 with progress, then the answer kept); the unit's
// noise is required and a bad plan option is named.
TEST(Http, ACampaignIsPredictedBeforeItRuns) {
  LocalDaemon d("plan", true);
  const Client viewer{d.service->port(), kViewerToken};
  const std::string campaign = R"({"name": "p", "program": "direct-short", "rate_hz": 20)";
  const std::string with_noise = campaign + R"(, "plan": {"arw_deg_rth": 0.0005, "vrw_mps_rth": 0.002}})";
  HttpResult r = viewer.post("/api/campaigns/plan", with_noise);
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(120);
  bool saw_pending = false;
  while (r.status == 202 && std::chrono::steady_clock::now() < deadline) {
    saw_pending = true;
    EXPECT_TRUE(r.json_body().contains("progress")) << r.body;
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
    r = viewer.post("/api/campaigns/plan", with_noise);
  }
  ASSERT_EQ(r.status, 200) << r.body;
  EXPECT_TRUE(saw_pending) << "the first request starts a job: 202";
  const json p = r.json_body();
  EXPECT_EQ(p.at("format"), "imucal-plan/1");
  EXPECT_EQ(p.at("rate_hz").get<double>(), 20.0);
  const json direct = p.at("stages").at("direct");
  EXPECT_EQ(direct.at("status"), "done") << direct.dump();
  EXPECT_GT(direct.at("sigma").at("gyro").at("bias_dph").at(0).get<double>(), 0.0);
  EXPECT_GT(direct.at("estimates").at("accel.scale_ppm.z").at(1).get<double>(), 0.0);
  // The same body again: the kept answer at once.
  EXPECT_EQ(viewer.post("/api/campaigns/plan", with_noise).status, 200);

  const auto no_noise = viewer.post("/api/campaigns/plan", campaign + "}");
  HttpResult refused = no_noise;
  while (refused.status == 202 && std::chrono::steady_clock::now() < deadline) {
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
    refused = viewer.post("/api/campaigns/plan", campaign + "}");
  }
  EXPECT_EQ(refused.status, 422) << refused.body;
  EXPECT_NE(refused.body.find("no noise"), std::string::npos) << refused.body;

  const auto bad = viewer.post("/api/campaigns/plan", campaign + R"(, "plan": {"rate_hz": 0}})");
  EXPECT_EQ(bad.status, 422);
  EXPECT_NE(bad.body.find("plan.rate_hz"), std::string::npos) << bad.body;
  const auto typo = viewer.post("/api/campaigns/plan", campaign + R"(, "plan": {"arw": 1}})");
  EXPECT_EQ(typo.status, 422);
  EXPECT_NE(typo.body.find(R"(plan: unknown key \"arw\")"), std::string::npos) << typo.body;
}
