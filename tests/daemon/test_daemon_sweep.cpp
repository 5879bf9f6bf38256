// The route sweep (issue 33): every route docs/api.md documents, on a run of every kind and state,
// as operator, as viewer and without credentials, over the real socket: no 5xx, no crash, no reply
// slower than kReplyBound, and the code each role must get. The table of routes below is the
// test's data; a route docs/api.md documents without a row here (or a row for a route it does not
// document) fails the test, so a new endpoint cannot go unswept.
//
// The runs: every built-in program to its end (the short versions where there are: direct-short,
// rate-steps-short, tumble-short, warm-up-short, repeatability-short with its power-cycle prompts
// answered, thermal-short with its built-in chamber profile; lever-arm, navigation, noise,
// evaluate, which have none; and the campaign `full`), one stopped early, one aborted, one failed
// (its start model names a campaign without one), one never started, one running and one queued
// behind it. Chosen for time: every finished run at time_scale 0 (as fast as the machine goes) and
// 10 Hz, a tenth of the default rate, at which every stage still finishes (the test asserts the
// lever-arm and full reports' figures); the stopped and aborted runs at time_scale 50, the running
// one in real time. Measured on the suite's loaded 2-core machine in release: the runs 34-41 s,
// the whole test 46-55 s (1887 calls, the slowest reply 0.3-0.5 s: the first download of `full`'s
// recording, then written on the request); under ASan+UBSan beside a compile, the runs 152 s, the
// test 184 s, the slowest 0.7 s. Since the bundles are written by jobs (the first request answers
// 202), on an idle machine: 2193 calls, the test 20 s, the slowest reply 0.03 s.
#include <algorithm>
#include <fstream>
#include <regex>
#include <set>
#include <sstream>

#include <gtest/gtest.h>

#include "service_fixture.hpp"
#include "tests/test_paths.hpp"

using namespace imucal;
using namespace imucal::daemontest;

namespace {

// The slowest reply the sweep accepts: generous for a loaded 2-core machine under ASan. The
// recording bundles are written by jobs (the first request answers 202 at once); a later caller
// may download one (`full`'s is 45 MB).
constexpr double kReplyBound_s = 30.0;

struct SweepRun {
  std::string label;  // what the sweep says it is
  std::int64_t id = 0;
  json detail;        // GET /api/campaigns/{id} just before its routes are swept
  std::string state() const { return detail.value("state", std::string()); }
  bool has_model() const { return detail.value("has_model", false); }
  bool recorded() const { return detail.contains("run_db") && detail.at("run_db").is_string(); }
  bool final() const { return state() == "done" || state() == "failed" || state() == "aborted"; }
  bool busy() const { return state() != "created" && !final() && state() != "interrupted"; }  // queued or active
};

enum class Access { open, viewer, operator_ };

struct Row {
  using Codes = std::function<std::set<int>(const SweepRun&)>;
  using Text = std::function<std::string(const SweepRun&)>;
  Row(const char* m, std::string r, Access a, Codes c, Text t, Text b = {})
      : method(m), route(std::move(r)), access(a), codes(std::move(c)), target(std::move(t)), body(std::move(b)) {}
  const char* method;
  std::string route;  // as docs/api.md names it ({id} a campaign, {serial} its unit; alarms {id} too)
  Access access;
  // The codes a caller allowed on the route may get on this run, and the target and body to send.
  Codes codes;
  Text target;
  Text body;  // none: no body
};

std::string campaign_path(const SweepRun& r) { return "/api/campaigns/" + std::to_string(r.id); }

// Where a command applies, as docs/api.md's table of commands says.
std::set<int> command_codes(const std::string& command, const std::string& state) {
  static const std::map<std::string, std::set<std::string>> from = {
      {"start", {"created"}},
      {"pause", {"running"}},
      {"resume", {"paused", "interrupted"}},
      {"stop", {"running", "pausing", "paused", "suspended"}},
      {"abort", {"created", "queued", "interrupted", "running", "pausing", "paused", "suspended", "stopping"}}};
  return {from.at(command).contains(state) ? 200 : 409};
}

// The state a transient one settles in by itself while the sweep looks.
std::string settled(const std::string& state) {
  if (state == "pausing") return "paused";
  if (state == "stopping") return "done";
  if (state == "aborting") return "aborted";
  return state;
}

std::set<std::string> documented_routes() {
  std::ifstream in(imucaltest::source_dir() + "/docs/api.md");
  std::set<std::string> out;
  const std::regex route("`(GET|POST|PUT|PATCH|DELETE) (/api/[^` ?]*)[^`]*`");
  std::string line;
  while (std::getline(in, line)) {
    if (!line.starts_with("#")) continue;
    for (std::sregex_iterator it(line.begin(), line.end(), route), end; it != end; ++it) {
      const std::string method = (*it)[1], path = (*it)[2];
      // `/api/campaigns/{id}/start|pause|...`: one route per alternative of the last segment.
      const auto slash = path.rfind('/');
      std::stringstream alternatives(path.substr(slash + 1));
      std::string last;
      while (std::getline(alternatives, last, '|')) out.insert(method + " " + path.substr(0, slash + 1) + last);
    }
  }
  return out;
}

std::vector<Row> rows(const std::int64_t model_run) {
  const auto always = [](int code) { return [code](const SweepRun&) { return std::set<int>{code}; }; };
  const auto fixed = [](std::string t) { return [t](const SweepRun&) { return t; }; };
  const auto sub = [](std::string tail) { return [tail](const SweepRun& r) { return campaign_path(r) + tail; }; };
  const auto analysis = [](const SweepRun& r) -> std::set<int> {
    if (r.busy()) return {409};
    if (!r.recorded()) return {404};
    return {200, 202};  // 202 while computing (or writing the bundle); 200 the answer (or the bundle)
  };
  std::vector<Row> t = {
      {"POST", "/api/login", Access::open, always(200), fixed("/api/login"),
       [](const SweepRun&) { return json{{"token", kViewerToken}}.dump(); }},
      {"POST", "/api/logout", Access::open, always(200), fixed("/api/logout")},
      {"GET", "/api/me", Access::viewer, always(200), fixed("/api/me")},
      {"GET", "/api/health", Access::open, always(200), fixed("/api/health")},
      {"GET", "/api/status", Access::viewer, always(200), fixed("/api/status")},
      {"GET", "/api/lab", Access::viewer, always(200), fixed("/api/lab")},
      {"GET", "/api/programs", Access::viewer, always(200), fixed("/api/programs")},
      {"GET", "/api/schema", Access::viewer, always(200), fixed("/api/schema")},
      {"GET", "/api/suspenders", Access::viewer, always(200), fixed("/api/suspenders")},
      {"POST", "/api/campaigns/validate", Access::viewer, always(200), fixed("/api/campaigns/validate"),
       [](const SweepRun&) { return R"({"name": "sweep", "program": "direct-short"})"; }},
      {"POST", "/api/campaigns/plan", Access::viewer, [](const SweepRun&) { return std::set<int>{200, 202}; },
       fixed("/api/campaigns/plan"),
       [](const SweepRun&) { return R"({"name": "sweep", "program": "direct-short",
                        "plan": {"rate_hz": 1, "arw_deg_rth": 0.001, "vrw_mps_rth": 0.01}})"; }},
      {"POST", "/api/campaigns", Access::operator_, always(201), fixed("/api/campaigns"),
       [](const SweepRun&) { return R"({"name": "sweep: posted", "program": "direct-short"})"; }},
      {"GET", "/api/campaigns", Access::viewer, always(200), fixed("/api/campaigns")},
      {"GET", "/api/campaigns/{id}", Access::viewer, always(200), sub("")},
      {"GET", "/api/campaigns/{id}/events.csv", Access::viewer, always(200), sub("/events.csv")},
      {"GET", "/api/alarms", Access::viewer, always(200),
       [](const SweepRun& r) { return "/api/alarms?all=1&campaign=" + std::to_string(r.id); }},
      {"GET", "/api/audit", Access::viewer, always(200),
       [](const SweepRun& r) { return "/api/audit?subject=campaign%20" + std::to_string(r.id) + "&limit=20"; }},
      {"POST", "/api/alarms/{id}/ack", Access::operator_,
       [](const SweepRun& r) { return r.detail.at("alarms").empty() ? std::set<int>{404} : std::set<int>{200, 409}; },
       [](const SweepRun& r) {
         const json& alarms = r.detail.at("alarms");
         return "/api/alarms/" + (alarms.empty() ? std::string("999999") : alarms[0].at("id").dump()) + "/ack";
       }},
      {"POST", "/api/campaigns/{id}/prompt", Access::operator_, always(409), sub("/prompt"),
       [](const SweepRun&) { return R"({"answer": "done"})"; }},
      {"GET", "/api/campaigns/{id}/report", Access::viewer, always(200), sub("/report")},
      {"GET", "/api/campaigns/{id}/model", Access::viewer,
       [](const SweepRun& r) { return std::set<int>{r.has_model() ? 200 : 404}; }, sub("/model")},
      {"POST", "/api/campaigns/{id}/accept", Access::operator_,
       [](const SweepRun& r) {
         return r.final() && r.has_model() && !r.detail.value("complete", false) ? std::set<int>{200, 409} : std::set<int>{409};
       },
       sub("/accept"), [](const SweepRun&) { return R"({"reason": "the sweep accepts what it may"})"; }},
      // No run of the sweep has a certificate stating another g than the configured one.
      {"POST", "/api/campaigns/{id}/recalibrate", Access::operator_, always(409), sub("/recalibrate"),
       [](const SweepRun&) { return R"({"reason": "the sweep asks for what it may"})"; }},
      {"GET", "/api/campaigns/{id}/series", Access::viewer,
       [](const SweepRun& r) { return std::set<int>{r.recorded() ? 200 : 404}; }, sub("/series?points=50")},
      {"GET", "/api/campaigns/{id}/certificate", Access::viewer,
       [](const SweepRun& r) {
         if (!r.final() || !r.has_model()) return std::set<int>{409};
         // A partial run has one once the accept row above has accepted it (as operator).
         return r.detail.value("complete", false) ? std::set<int>{200} : std::set<int>{200, 409};
       },
       sub("/certificate")},
      {"GET", "/api/certificates/{number}", Access::viewer, always(404), fixed("/api/certificates/SWEEP-2026-999999")},
      {"GET", "/api/certificates/{number}/page", Access::viewer, always(404), fixed("/api/certificates/SWEEP-2026-999999/page")},
      {"PUT", "/api/certificates/{number}/page", Access::operator_, always(404), fixed("/api/certificates/SWEEP-2026-999999/page"),
       [](const SweepRun&) { return R"({"html": "<p>SWEEP-2026-999999</p>"})"; }},
      {"GET", "/api/campaigns/{id}/progress", Access::viewer, always(200), sub("/progress")},
      {"GET", "/api/campaigns/{id}/truth", Access::viewer,
       [](const SweepRun& r) { return std::set<int>{r.has_model() ? 200 : 404}; }, sub("/truth")},
      {"GET", "/api/campaigns/{id}/recording", Access::viewer, analysis, sub("/recording")},
      {"GET", "/api/campaigns/{id}/allan", Access::viewer, analysis, sub("/allan")},
      {"GET", "/api/campaigns/{id}/thermal", Access::viewer, analysis, sub("/thermal")},
      {"GET", "/api/campaigns/{id}/evaluation", Access::viewer, analysis, sub("/evaluation")},
      {"GET", "/api/imus", Access::viewer, always(200), fixed("/api/imus")},
      {"GET", "/api/imus/{serial}", Access::viewer, always(200),
       [](const SweepRun& r) { return "/api/imus/SWEEP-" + std::to_string(r.id); }},
      // No shared archive in the sweep's configuration: 404 saying so (test_daemon_lab.cpp has one).
      {"GET", "/api/archive/{stand}/{campaign}/recording", Access::viewer, always(404),
       [](const SweepRun& r) { return "/api/archive/sweep-stand/" + std::to_string(r.id) + "/recording"; }},
      {"GET", "/api/imus/{serial}/history.csv", Access::viewer, always(200),
       [](const SweepRun& r) { return "/api/imus/SWEEP-" + std::to_string(r.id) + "/history.csv"; }},
      {"GET", "/api/compare", Access::viewer,
       [](const SweepRun& r) { return r.has_model() ? std::set<int>{200, 409} : std::set<int>{409}; },
       [model_run](const SweepRun& r) { return "/api/compare?a=" + std::to_string(r.id) + "&b=" + std::to_string(model_run); }},
      {"GET", "/api/limits", Access::viewer, always(200), fixed("/api/limits")},
      {"PUT", "/api/limits", Access::operator_, always(200), fixed("/api/limits"),
       [](const SweepRun&) { return R"({"format": "imucal-limits/1", "part_numbers": {"SWEEP": {"gyro.bias_dph": {"max_abs": 1}}}})"; }},
  };
  // The commands last: they change the run (a queued one is aborted, the running one paused,
  // stopped), so that every read above saw it as it was.
  for (const std::string command : {"start", "pause", "resume", "stop", "abort"})
    t.emplace_back("POST", "/api/campaigns/{id}/" + command, Access::operator_,
                   [command](const SweepRun& r) {
                     std::set<int> codes = command_codes(command, r.state());
                     for (const int code : command_codes(command, settled(r.state()))) codes.insert(code);
                     return codes;
                   },
                   sub("/" + command));
  return t;
}

struct Caller {
  const char* name;
  std::string token;  // empty: no credentials
  bool may(Access a) const {
    if (a == Access::open) return true;
    if (token.empty()) return false;
    return a == Access::viewer || token == kOperatorToken;
  }
};

}  // namespace

TEST(RouteSweep, EveryDocumentedRouteOnEveryKindOfRunAsEveryRole) {
  const auto t_start = std::chrono::steady_clock::now();
  LocalDaemon d("sweep", true);
  const std::uint16_t port = d.service->port();
  const auto elapsed = [&] { return std::chrono::duration<double>(std::chrono::steady_clock::now() - t_start).count(); };

  // ---- the runs ---------------------------------------------------------------------------------
  std::vector<SweepRun> runs;
  int serial = 0;
  const auto post = [&](const std::string& label, json campaign) {
    campaign["name"] = "sweep: " + label;
    campaign["imu"] = {{"serial", "SWEEP-" + std::to_string(++serial)}, {"part_number", "SWEEP"}};
    if (!campaign.contains("rate_hz")) campaign["rate_hz"] = 10;
    if (!campaign.contains("time_scale")) campaign["time_scale"] = 0;
    SweepRun r;
    r.label = label;
    r.id = d.post_campaign(campaign);
    EXPECT_EQ(serial, r.id) << "a unit's serial is its campaign's id (the table names it so)";
    runs.push_back(r);
    return r.id;
  };
  const std::vector<std::string> finished = {"direct-short", "lever-arm", "navigation", "noise",
                                             "evaluate", "thermal-short", "rate-steps-short", "tumble-short",
                                             "warm-up-short", "repeatability-short", "full"};
  for (const auto& program : finished) post(program, {{"program", program}, {"truth", noisy_truth()}});
  for (const auto& r : runs) ASSERT_EQ(d.command(r.id, "start"), 200) << r.label;
  // The runs go one after the other (one bench); the repeatability program's power cycles are
  // answered as they are asked.
  for (const auto& r : runs) {
    const json c = d.wait_for(r.id, [&](const json& now) {
      if (now.value("prompt", json(nullptr)).is_object())
        d.call("POST", campaign_path(r) + "/prompt", R"({"answer": "done"})");
      const auto s = now.value("state", "");
      return s == "done" || s == "failed" || s == "aborted";
    }, 900.0);
    ASSERT_EQ(c.at("state"), "done") << r.label << ": " << c.value("error", json()).dump();
  }
  const std::int64_t model_run = runs.front().id;  // direct-short: a model to compare with
  const double runs_s = elapsed();

  const auto stopped = post("stopped early", {{"program", "direct-short"}, {"time_scale", 50}});
  ASSERT_EQ(d.command(stopped, "start"), 200);
  d.wait_for(stopped, [](const json& c) { return c.value("program_time_s", 0.0) > 100.0; });
  ASSERT_EQ(d.command(stopped, "stop"), 200);
  ASSERT_EQ(d.wait_final(stopped).at("state"), "done");
  const auto aborted = post("aborted", {{"program", "direct-short"}, {"time_scale", 50}});
  ASSERT_EQ(d.command(aborted, "start"), 200);
  d.wait_for(aborted, [](const json& c) { return c.value("program_time_s", 0.0) > 50.0; });
  ASSERT_EQ(d.command(aborted, "abort"), 200);
  ASSERT_EQ(d.wait_final(aborted).at("state"), "aborted");
  // Never started, and the start model of the one that fails: it has no model when that starts.
  const auto created = post("never started", {{"program", "direct-short"}});
  const auto failed = post("failed", {{"program", "direct-short"}, {"model", created}});
  ASSERT_EQ(d.command(failed, "start"), 200);
  ASSERT_EQ(d.wait_final(failed).at("state"), "failed");
  // Real time: the noise program's 2 h stay running through the sweep, the next one queued.
  const auto running = post("running", {{"program", "noise"}, {"time_scale", 1}});
  const auto queued = post("queued", {{"program", "direct-short"}});
  ASSERT_EQ(d.command(running, "start"), 200);
  d.wait_state(running, "running");
  ASSERT_EQ(d.command(queued, "start"), 200);
  ASSERT_EQ(d.campaign(queued).at("state"), "queued");
  // The sweep's order: the queued run before the running one, whose commands end it.
  std::stable_partition(runs.begin(), runs.end(), [&](const SweepRun& r) { return r.id != running; });

  // ---- the table against the docs ----------------------------------------------------------------
  const auto table = rows(model_run);
  std::set<std::string> swept;
  for (const Row& row : table) swept.insert(std::string(row.method) + " " + row.route);
  EXPECT_EQ(swept.size(), table.size()) << "a route with two rows";
  const auto documented = documented_routes();
  ASSERT_GE(documented.size(), 30u) << "docs/api.md's headings were not parsed";
  for (const auto& route : documented) EXPECT_TRUE(swept.contains(route)) << "documented but not swept: " << route;
  for (const auto& route : swept) EXPECT_TRUE(documented.contains(route)) << "swept but not documented: " << route;

  // ---- the sweep ----------------------------------------------------------------------------------
  const std::vector<Caller> callers = {{"anonymous", ""}, {"viewer", kViewerToken}, {"operator", kOperatorToken}};
  int calls = 0;
  double slowest_s = 0.0;
  std::string slowest;
  for (SweepRun& run : runs) {
    for (const Row& row : table) {
      // Every call sees the run as it is now (the commands before may have changed it).
      run.detail = d.campaign(run.id);
      ASSERT_TRUE(run.detail.is_object());
      for (const Caller& who : callers) {
        const std::string target = row.target(run);
        std::map<std::string, std::string> headers;
        if (!who.token.empty()) headers["Authorization"] = "Bearer " + who.token;
        const auto t0 = std::chrono::steady_clock::now();
        const HttpResult r = http_request(port, row.method, target, row.body ? row.body(run) : std::string(), headers);
        const double took_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
        ++calls;
        const std::string what = std::string(row.method) + " " + target + " as " + who.name + " on '" + run.label +
                                 "' (" + run.state() + ")";
        if (took_s > slowest_s) {
          slowest_s = took_s;
          slowest = what;
        }
        EXPECT_LE(took_s, kReplyBound_s) << what;
        ASSERT_NE(r.status, 0) << what << ": no reply (the daemon died?)";
        EXPECT_LT(r.status, 500) << what << ": " << r.body.substr(0, 300);
        std::set<int> want = who.may(row.access) ? row.codes(run) : std::set<int>{who.token.empty() ? 401 : 403};
        EXPECT_TRUE(want.contains(r.status)) << what << ": " << r.status << " " << r.body.substr(0, 300);
        if (r.status >= 400) {
          EXPECT_FALSE(r.json_body().value("error", std::string()).empty()) << what << ": " << r.body.substr(0, 300);
        }
        // The report of a lever-arm and a full run: the crash that opened issue 33.
        if (row.route == "/api/campaigns/{id}/report" && r.status == 200 &&
            (run.label == "lever-arm" || run.label == "full")) {
          const json report = r.json_body();
          std::size_t figures = 0;
          for (const auto& test : report.value("tests", json::array())) figures += test.value("figures", json::array()).size();
          EXPECT_GT(figures, 0u) << what << ": " << r.body.substr(0, 500);
          bool lever_arm = false;
          for (const auto& test : report.value("tests", json::array())) lever_arm = lever_arm || test.value("test", "") == "lever-arm";
          EXPECT_TRUE(lever_arm) << what << ": no lever-arm test: " << r.body.substr(0, 500);
        }
      }
    }
  }
  EXPECT_EQ(http_request(port, "GET", "/api/health").status, 200) << "alive at the end";
  std::printf("route sweep: %zu documented routes, %zu runs, %d calls; the runs took %.1f s, all %.1f s; "
              "slowest reply %.2f s (%s)\n",
              documented.size(), runs.size(), calls, runs_s, elapsed(), slowest_s, slowest.c_str());
}
