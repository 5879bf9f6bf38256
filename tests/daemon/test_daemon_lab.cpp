// The lab overview (issue 38, deliverable 2): a started imucald registers itself in its registry
// (here its own database) and reports its state every registry.heartbeat_s; GET /api/lab lists it
// online, with the run it runs and its progress, and the run gone once it ended. The heartbeat's
// own parts (registration again, shutdown at once) on a registry of the test's.
#include <gtest/gtest.h>

#include <algorithm>
#include <chrono>
#include <filesystem>
#include <functional>
#include <memory>
#include <optional>
#include <set>
#include <string>

#include "daemon/production/lab.hpp"
#include "daemon/production/limits_follower.hpp"
#include "daemon/registry/sqlite_registry.hpp"
#include "daemon/registry/stand_heartbeat.hpp"
#include "service_fixture.hpp"
#include "tests/postgres_server.hpp"

using namespace imucal;
using namespace imucal::daemontest;

namespace {

// Polls GET /api/lab until this stand's entry satisfies `pred` (a generous deadline: the machine
// may be loaded); the last entry seen.
json wait_for_stand(LocalDaemon& d, const std::function<bool(const json&)>& pred, double timeout_s = 60.0) {
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::duration<double>(timeout_s);
  json last;
  while (std::chrono::steady_clock::now() < deadline) {
    const auto r = d.call("GET", "/api/lab", "", kViewerToken);
    EXPECT_EQ(r.status, 200) << r.body;
    last = json::parse(r.body);
    for (const json& s : last.at("stands"))
      if (s.value("this", false) && pred(s)) return s;
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }
  ADD_FAILURE() << "timed out waiting on this stand in GET /api/lab: " << last.dump().substr(0, 3000);
  return {};
}

// How a stand joins the registry `conninfo` as `stand`, heartbeats every 0.1 s, then `more`.
std::function<void(daemon::DaemonConfig&)> joins(const std::string& conninfo, const std::string& stand,
                                                 std::function<void(daemon::DaemonConfig&)> more = {}) {
  return [conninfo, stand, more](daemon::DaemonConfig& c) {
    c.registry.postgresql = conninfo;
    c.registry.stand = stand;
    c.registry.heartbeat_s = 0.1;
    if (more) more(c);
  };
}

}  // namespace

TEST(Lab, AStartedStandIsOnlineAndShowsWhatItRunsAndItsProgress) {
  LocalDaemon d("lab", false, [](daemon::DaemonConfig& c) {
    c.registry.stand = "stand-7";
    c.registry.url = "http://stand-7.lab.example:8080";
    c.registry.heartbeat_s = 0.1;
  });
  const json idle = wait_for_stand(d, [](const json& s) { return s.at("online").get<bool>(); });
  EXPECT_EQ(idle.at("name"), "stand-7");
  EXPECT_EQ(idle.at("url"), "http://stand-7.lab.example:8080");
  EXPECT_EQ(idle.at("bench"), d.config.devices);
  EXPECT_EQ(idle.at("version"), d.get("/api/status").at("version"));
  EXPECT_DOUBLE_EQ(idle.at("heartbeat_s").get<double>(), 0.1);
  EXPECT_TRUE(idle.at("run").is_null()) << idle.dump();
  EXPECT_EQ(idle.at("alarms").at("active"), 0);
  EXPECT_LE(idle.at("registered_at").get<std::string>(), idle.at("last_seen").get<std::string>());
  // The heartbeat goes on: last_seen moves.
  const std::string first_seen = idle.at("last_seen");
  wait_for_stand(d, [&](const json& s) { return s.at("last_seen").get<std::string>() > first_seen; });

  // Real time: the noise program's hours stay running while the lab is asked.
  const auto id = d.post_campaign({{"name", "lab run"},
                                   {"program", "noise"},
                                   {"rate_hz", 10},
                                   {"time_scale", 1},
                                   {"imu", {{"serial", "LAB-1"}, {"part_number", "P-1"}}}});
  ASSERT_EQ(d.command(id, "start"), 200);
  const json running = wait_for_stand(d, [&](const json& s) {
    return s.at("run").is_object() && s.at("run").at("id") == id && s.at("run").at("progress").get<double>() > 0.0;
  });
  ASSERT_TRUE(running.at("run").is_object()) << running.dump();
  EXPECT_EQ(running.at("run").at("name"), "lab run");
  EXPECT_EQ(running.at("run").at("state"), "running");
  EXPECT_EQ(running.at("run").at("imu").at("serial"), "LAB-1");
  EXPECT_LT(running.at("run").at("progress").get<double>(), 1.0);
  EXPECT_GT(running.at("run").at("program_time_s").get<double>(), 0.0);
  EXPECT_TRUE(running.at("online").get<bool>());

  ASSERT_EQ(d.command(id, "abort"), 200);
  ASSERT_EQ(d.wait_final(id).at("state"), "aborted");
  const json after = wait_for_stand(d, [](const json& s) { return s.at("run").is_null(); });
  EXPECT_TRUE(after.at("online").get<bool>());
}

// A stand not seen for three of its periods shows offline; a state that does not parse shows the
// stand without one.
TEST(Lab, AStandNotSeenForThreePeriodsIsOffline) {
  const std::int64_t now = 1'800'000'000'000;
  const std::vector<daemon::StandRow> stands = {
      {"a", "sim", "http://a:8080", "1", 1000, now - 60000, now - 3000, R"({"run":{"id":1},"queue":2})"},
      {"b", "wire", "http://b:8080", "1", 1000, now - 60000, now - 3001, "not json"}};
  const json lab = daemon::lab_json(stands, now, "b");
  ASSERT_EQ(lab.at("stands").size(), 2U);
  const json& a = lab.at("stands")[0];
  const json& b = lab.at("stands")[1];
  EXPECT_TRUE(a.at("online").get<bool>());
  EXPECT_FALSE(a.at("this").get<bool>());
  EXPECT_EQ(a.at("run").at("id"), 1);
  EXPECT_EQ(a.at("queue"), 2);
  EXPECT_FALSE(b.at("online").get<bool>());
  EXPECT_TRUE(b.at("this").get<bool>());
  EXPECT_TRUE(b.at("run").is_null());
  EXPECT_EQ(lab.at("stand"), "b");
}

namespace {

bool poll(const std::function<bool()>& done, double timeout_s = 60.0) {
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::duration<double>(timeout_s);
  while (!done()) {
    if (std::chrono::steady_clock::now() > deadline) return false;
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
  }
  return true;
}

}  // namespace

// The limits followed last live in the stand's database: a restart under the same limits reissues
// nothing; limits changed while the stand was off are followed at its first beat, for the part
// numbers they changed only; a stand that never followed any reissues every part number once.
TEST(Lab, TheLimitsFollowedLastOutliveARestart) {
  const std::string dir = scratch_dir("lab-limits-followed");
  const auto limits = [](double max_abs) {
    return json{{"format", "imucal-limits/1"},
                {"part_numbers", {{"PN-1", {{"gyro.bias_dph", {{"max_abs", max_abs}}}}},
                                  {"PN-2", {{"gyro.bias_dph", {{"max_abs", 1.0}}}}}}}};
  };
  json in_force = limits(0.5);
  std::vector<std::optional<std::set<std::string>>> reissued;
  const auto follower = [&](daemon::DaemonDb& db) {
    return std::make_unique<daemon::LimitsFollower>(
        db, [&] { return in_force; },
        [&](const std::optional<std::set<std::string>>& changed, const std::string&) { reissued.push_back(changed); });
  };
  {
    daemon::DaemonDb db(dir + "/imucald.db");
    auto f = follower(db);
    f->follow();
    ASSERT_EQ(reissued.size(), 1U);
    EXPECT_FALSE(reissued[0]) << "a stand that never followed limits reissues every part number";
    f->follow();
    EXPECT_EQ(reissued.size(), 1U);
  }
  {
    daemon::DaemonDb db(dir + "/imucald.db");  // restarted, the limits unchanged
    follower(db)->follow();
    EXPECT_EQ(reissued.size(), 1U) << "a restart under the same limits reissued";
  }
  in_force = limits(0.25);  // put by another stand while this one was off
  {
    daemon::DaemonDb db(dir + "/imucald.db");
    auto f = follower(db);
    f->follow();
    ASSERT_EQ(reissued.size(), 2U);
    EXPECT_EQ(reissued[1], std::optional<std::set<std::string>>(std::set<std::string>{"PN-1"}));
    // The stand's own PUT reissues at once and records the limits as followed (replace_limits):
    // the running follower's next beat has nothing to do.
    in_force = limits(0.125);
    daemon::LimitsFollower::record_followed(db, in_force);
    f->follow();
    EXPECT_EQ(reissued.size(), 2U) << "the follower reissued what the stand's own PUT had";
  }
}

// The SQLite registry knows one stand: another registered in its place makes this one's reports
// unknown, and its heartbeat registers it again. A stop does not wait for the period.
TEST(Lab, TheHeartbeatRegistersAgainWhenForgottenAndStopsAtOnce) {
  const std::string dir = scratch_dir("lab-heartbeat");
  daemon::DaemonDb db(dir + "/imucald.db");
  daemon::CertificateSequence sequence(dir + "/sequence.json");
  daemon::SqliteRegistry registry(db, sequence, "s", dir + "/limits.json");
  const daemon::StandRow identity{"s", "sim", "http://s:1", "v", 0, 0, 0, "{}"};
  const auto has = [&](const std::string& name, const std::string& state) {
    const auto stands = registry.stands();
    return stands.size() == 1 && stands[0].name == name && stands[0].state_json == state;
  };
  auto heartbeat = std::make_unique<daemon::StandHeartbeat>(registry, identity, std::chrono::hours(1),
                                                            [] { return json{{"run", nullptr}}; });
  ASSERT_TRUE(poll([&] { return has("s", R"({"run":null})"); }));
  EXPECT_EQ(registry.stands()[0].heartbeat_ms, 3600000);
  const auto t0 = std::chrono::steady_clock::now();
  heartbeat.reset();  // the hour is not waited for
  EXPECT_LT(std::chrono::steady_clock::now() - t0, std::chrono::seconds(30));

  heartbeat = std::make_unique<daemon::StandHeartbeat>(registry, identity, std::chrono::milliseconds(10),
                                                       [] { return json{{"queue", 0}}; });
  ASSERT_TRUE(poll([&] { return has("s", R"({"queue":0})"); }));
  db.register_stand({"other", "sim", "http://o:1", "v", 10, 1, 1, "{}"});  // "s" forgotten
  ASSERT_TRUE(poll([&] { return has("s", R"({"queue":0})"); })) << registry.stands().size();
  heartbeat.reset();
}

// Issue 38's lab: two stands on one PostgreSQL registry each list both; a stand stopped shows
// offline on the other's page once three of its heartbeats are missed.
TEST(Lab, TwoStandsOnOnePostgresRegistrySeeEachOther) {
  std::string conninfo;
  IMUCALTEST_FRESH_POSTGRES_DATABASE(conninfo, "lab");
  const auto on_registry = [&](const std::string& stand) { return joins(conninfo, stand); };
  LocalDaemon a("lab-stand-a", false, on_registry("stand-a"));
  auto b = std::make_unique<LocalDaemon>("lab-stand-b", false, on_registry("stand-b"));
  const auto both_online = [&](LocalDaemon& d) {
    const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(60);
    json lab;
    while (std::chrono::steady_clock::now() < deadline) {
      lab = d.get("/api/lab");
      const json& s = lab.at("stands");
      if (s.size() == 2 && s[0].at("online").get<bool>() && s[1].at("online").get<bool>()) return lab;
      std::this_thread::sleep_for(std::chrono::milliseconds(20));
    }
    ADD_FAILURE() << "not both online: " << lab.dump();
    return lab;
  };
  const json seen_by_a = both_online(a);
  EXPECT_EQ(seen_by_a.at("stand"), "stand-a");
  EXPECT_EQ(seen_by_a.at("stands")[0].at("name"), "stand-a");
  EXPECT_TRUE(seen_by_a.at("stands")[0].at("this").get<bool>());
  EXPECT_EQ(seen_by_a.at("stands")[1].at("name"), "stand-b");
  EXPECT_FALSE(seen_by_a.at("stands")[1].at("this").get<bool>());
  EXPECT_TRUE(both_online(*b).at("stands")[1].at("this").get<bool>());

  b.reset();  // stand b stops: it is no longer heard from
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(60);
  json lab;
  while (std::chrono::steady_clock::now() < deadline) {
    lab = a.get("/api/lab");
    if (!lab.at("stands")[1].at("online").get<bool>()) break;
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }
  EXPECT_FALSE(lab.at("stands")[1].at("online").get<bool>()) << lab.dump();
  EXPECT_TRUE(lab.at("stands")[0].at("online").get<bool>()) << lab.dump();
}

TEST(Lab, TheStandsAddressIsConfiguredOrItsHttpServers) {
  daemon::DaemonConfig c = daemon::parse_config(R"({"registry": {"url": "https://stand-3.lab", "heartbeat_s": 2}})", "test");
  EXPECT_EQ(daemon::stand_url(c, 1234), "https://stand-3.lab");
  EXPECT_DOUBLE_EQ(c.registry.heartbeat_s, 2.0);
  c.registry.url.clear();
  c.http.host = "10.0.0.7";
  EXPECT_EQ(daemon::stand_url(c, 8081), "http://10.0.0.7:8081");
  c.http.host = "::1";
  EXPECT_EQ(daemon::stand_url(c, 8081), "http://[::1]:8081");
  c.http.host = "0.0.0.0";
  EXPECT_NE(daemon::stand_url(c, 8081).find(":8081"), std::string::npos);
  EXPECT_EQ(daemon::stand_url(c, 8081).find("0.0.0.0"), std::string::npos);  // a name others reach
  try {
    (void)daemon::parse_config(R"({"registry": {"url": "stand-3.lab"}})", "test");
    ADD_FAILURE() << "an address without its scheme was taken";
  } catch (const std::exception& e) {
    EXPECT_NE(std::string(e.what()).find("registry.url"), std::string::npos) << e.what();
  }
}

// A stand's name is free text; its folder in the archive (and its segment in the archive's URLs)
// never climbs out, and two names never share one.
TEST(Lab, AStandsArchiveFolderStaysInsideTheArchive) {
  EXPECT_EQ(daemon::archive_folder("stand-1_a.b"), "stand-1_a.b");
  EXPECT_EQ(daemon::archive_folder("bay 2/left"), "bay%202%2Fleft");
  EXPECT_EQ(daemon::archive_folder(".."), "%2E%2E");
  EXPECT_EQ(daemon::archive_folder("."), "%2E");
  EXPECT_EQ(daemon::archive_folder("a%2Fb"), "a%252Fb");
  EXPECT_NE(daemon::archive_folder("a b"), daemon::archive_folder("a%20b"));
  EXPECT_EQ(daemon::archived_recording("/arch", "../x", 7).string(), "/arch/..%2Fx/campaign-7-recording.tar");
}

// Issue 38: a unit's history on one stand fetches another stand's recording from the lab's shared
// archive (each stand writes its ended runs' bundles there), and without it from the stand that
// holds it, at its registered address; that stand's campaign opens on that stand's page.
TEST(Lab, AnotherStandsRecordingIsFetchedFromTheArchiveElseFromThatStand) {
  std::string conninfo;
  IMUCALTEST_FRESH_POSTGRES_DATABASE(conninfo, "archive");
  const std::string archive = scratch_dir("lab-archive");
  const auto on_registry = [&](const std::string& stand) {
    return joins(conninfo, stand, [archive, stand](daemon::DaemonConfig& c) {
      c.registry.url = "http://" + stand + ".lab:8080";
      c.registry.archive_dir = archive;
    });
  };
  LocalDaemon a("lab-archive-a", false, on_registry("stand-a"));
  LocalDaemon b("lab-archive-b", false, on_registry("stand-b"));
  const auto id = a.post_campaign({{"name", "archived"}, {"program", "direct-short"}, {"rate_hz", 10}, {"time_scale", 0},
                                   {"imu", {{"serial", "ARCH-1"}}}});
  ASSERT_EQ(a.command(id, "start"), 200);
  ASSERT_EQ(a.wait_final(id, 300).at("state"), "done");
  const std::filesystem::path bundle = daemon::archived_recording(archive, "stand-a", id);

  // On stand b, once the bundle is in the archive: from there, served by b itself.
  const auto links_on = [&](LocalDaemon& d, const std::function<bool(const json&)>& pred) {
    const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(120);
    json links;
    while (std::chrono::steady_clock::now() < deadline) {
      const json unit = d.get("/api/imus/ARCH-1");
      if (unit.contains("calibrations") && !unit.at("calibrations").empty()) links = unit.at("calibrations")[0].at("links");
      if (links.is_object() && pred(links)) return links;
      std::this_thread::sleep_for(std::chrono::milliseconds(50));
    }
    ADD_FAILURE() << "links never as expected: " << links.dump();
    return links;
  };
  const json from_archive = links_on(b, [](const json& l) { return l.at("recording_from") == "archive"; });
  EXPECT_EQ(from_archive.at("recording"), "/api/archive/stand-a/" + std::to_string(id) + "/recording");
  EXPECT_EQ(from_archive.at("campaign_page"), "http://stand-a.lab:8080/#/campaigns/" + std::to_string(id));
  const auto fetched = b.call("GET", from_archive.at("recording").get<std::string>(), "", kViewerToken);
  ASSERT_EQ(fetched.status, 200) << fetched.body;
  EXPECT_EQ(fetched.file, bundle.string());
  EXPECT_GT(std::filesystem::file_size(bundle), 1000u);
  EXPECT_EQ(fetched.content_type, "application/x-tar");
  // On stand a, its own run from itself.
  const json own = links_on(a, [](const json& l) { return l.at("recording_from") == "this stand"; });
  EXPECT_EQ(own.at("recording"), "/api/campaigns/" + std::to_string(id) + "/recording");
  EXPECT_EQ(own.at("campaign_page"), "#/campaigns/" + std::to_string(id));

  // The archive without it: from stand a, at its registered address.
  std::filesystem::remove(bundle);
  const json from_stand = links_on(b, [](const json& l) { return l.at("recording_from") == "stand stand-a"; });
  EXPECT_EQ(from_stand.at("recording"), "http://stand-a.lab:8080/api/campaigns/" + std::to_string(id) + "/recording");
  EXPECT_EQ(b.call("GET", "/api/archive/stand-a/" + std::to_string(id) + "/recording", "", kViewerToken).status, 404);
  // Nothing outside the archive is served, whatever the stand's segment says.
  for (const char* stand : {"..", "%2E%2E", "..%2F..", "%2Fetc"})
    EXPECT_EQ(b.call("GET", std::string("/api/archive/") + stand + "/" + std::to_string(id) + "/recording", "", kViewerToken).status, 404)
        << stand;
}

// Issue 38: the limits are the lab's. Put on stand b, they supersede stand a's certificate whose
// verdict they change, at a's next heartbeat (b has none of a's to supersede); a's number comes
// from the lab's sequence.
TEST(Lab, LimitsPutOnOneStandSupersedeAnotherStandsCertificate) {
  std::string conninfo;
  IMUCALTEST_FRESH_POSTGRES_DATABASE(conninfo, "limits");
  const auto on_registry = [&](const std::string& stand) { return joins(conninfo, stand); };
  LocalDaemon a("lab-limits-a", false, on_registry("stand-a"));
  LocalDaemon b("lab-limits-b", false, on_registry("stand-b"));
  const auto id = a.post_campaign({{"name", "judged"}, {"program", "direct-short"}, {"rate_hz", 10}, {"time_scale", 0},
                                   {"imu", {{"serial", "LIM-1"}, {"part_number", "PN-LAB"}}}});
  ASSERT_EQ(a.command(id, "start"), 200);
  ASSERT_EQ(a.wait_final(id, 300).at("state"), "done");
  const std::string target = "/api/campaigns/" + std::to_string(id) + "/certificate";
  const auto certificate = [&] {
    const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(60);
    json c = a.get(target);
    while (!c.contains("number") && std::chrono::steady_clock::now() < deadline) {
      std::this_thread::sleep_for(std::chrono::milliseconds(50));
      c = a.get(target);
    }
    return c;
  };
  const json first = certificate();
  ASSERT_TRUE(first.contains("number")) << first.dump();
  EXPECT_TRUE(first.at("content").at("campaign").at("verdict").is_null());

  const json limits = {{"format", "imucal-limits/1"}, {"part_numbers", {{"PN-LAB", {{"gyro.bias_dph", {{"max_abs", 1.0}}}}}}}};
  ASSERT_EQ(b.call("PUT", "/api/limits", limits.dump()).status, 200);
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(60);
  json now = certificate();
  const std::string first_number = first.at("number").get<std::string>();
  while (now.value("number", "") == first_number && std::chrono::steady_clock::now() < deadline) {
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
    now = certificate();
  }
  ASSERT_NE(now.value("number", ""), first_number) << "stand a's certificate was not superseded";
  EXPECT_EQ(now.at("supersedes"), first.at("number"));
  EXPECT_EQ(now.at("reason"), "acceptance limits changed in the lab's registry");
  EXPECT_GT(now.at("sequence").get<std::int64_t>(), first.at("sequence").get<std::int64_t>());
  EXPECT_TRUE(now.at("content").at("campaign").at("verdict").is_object()) << now.at("content").dump().substr(0, 600);
  // Followed once: the next heartbeats leave it in force.
  std::this_thread::sleep_for(std::chrono::milliseconds(500));
  EXPECT_EQ(certificate().at("number"), now.at("number"));
}

// Issue 38: each stand's reference equipment is in the lab's registry with its heartbeat: a stand
// sees another stand's overdue rate table (and its own chamber in date) on GET /api/lab.
TEST(Lab, EveryStandsReferenceEquipmentIsJudgedOnTheLabPage) {
  std::string conninfo;
  IMUCALTEST_FRESH_POSTGRES_DATABASE(conninfo, "equipment");
  LocalDaemon a("lab-equipment-a", false, joins(conninfo, "stand-a", [](daemon::DaemonConfig& c) {
    c.reference_equipment.chamber = daemon::ReferenceInstrument{"ClimaCo", "CC-200", "C-4711", "2999-12-31", "", ""};
  }));
  LocalDaemon b("lab-equipment-b", false, joins(conninfo, "stand-b", [](daemon::DaemonConfig& c) {
    c.reference_equipment.table = daemon::ReferenceInstrument{"Acme Motion", "ATS-3", "T-0815", "2020-01-31", "DKD-123", ""};
  }));
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(60);
  json lab;
  const auto reported = [&] {
    const json& s = lab.at("stands");
    return s.size() == 2 && s[0].at("equipment").is_object() && s[1].at("equipment").is_object();
  };
  while (std::chrono::steady_clock::now() < deadline) {
    lab = a.get("/api/lab");
    if (reported()) break;
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }
  ASSERT_TRUE(reported()) << lab.dump();
  const json& own = lab.at("stands")[0].at("equipment");
  const json& other = lab.at("stands")[1].at("equipment");
  EXPECT_TRUE(own.at("table").is_null());
  EXPECT_FALSE(own.at("chamber").at("overdue").get<bool>());
  EXPECT_TRUE(other.at("chamber").is_null());
  EXPECT_EQ(other.at("table").at("serial"), "T-0815");
  EXPECT_TRUE(other.at("table").at("overdue").get<bool>()) << other.dump();
  EXPECT_NE(other.at("table").at("text").get<std::string>().find("was due for calibration on 2020-01-31"), std::string::npos)
      << other.dump();
}

// Issue 38: the lab's accounts. Put on stand a by an operator, an account signs in with its
// password on stand b, whose configuration does not name it, in its role; removed, it no longer
// does (within the accounts' freshness); the configuration's users are listed, no secret shown.
TEST(Lab, AnAccountPutOnOneStandSignsInOnAnother) {
  std::string conninfo;
  IMUCALTEST_FRESH_POSTGRES_DATABASE(conninfo, "users");
  LocalDaemon a("lab-users-a", false, joins(conninfo, "stand-a"));
  LocalDaemon b("lab-users-b", false, joins(conninfo, "stand-b"));
  const auto sign_in = [&](LocalDaemon& d, const std::string& password) {
    return d.call("POST", "/api/login", json{{"user", "grace"}, {"password", password}}.dump(), "");
  };
  EXPECT_EQ(sign_in(b, "grace's long password").status, 401);
  EXPECT_EQ(a.call("PUT", "/api/users/grace", R"({"role": "viewer", "password": "short"})").status, 400);
  EXPECT_EQ(a.call("PUT", "/api/users/viewer", R"({"role": "viewer", "password": "long enough"})").status, 409)
      << "a configured user's name";
  EXPECT_EQ(a.call("PUT", "/api/users/grace", R"({"role": "operator", "password": "grace's long password"})", kViewerToken)
                .status,
            403);
  const auto put = a.call("PUT", "/api/users/grace", R"({"role": "operator", "password": "grace's long password"})");
  ASSERT_EQ(put.status, 200) << put.body;

  // Stand b read the accounts at the first sign-in above: read again once kLabUsersFresh has passed
  // (one try: failed sign-ins are throttled).
  std::this_thread::sleep_for(daemon::Auth::kLabUsersFresh + std::chrono::milliseconds(200));
  const daemon::HttpReply in = sign_in(b, "grace's long password");
  ASSERT_EQ(in.status, 200) << in.body;
  EXPECT_EQ(json::parse(in.body).at("role"), "operator") << in.body;
  EXPECT_EQ(sign_in(b, "a wrong password!").status, 401);

  const json users = b.get("/api/users");
  bool listed = false;
  for (const json& u : users.at("users")) {
    EXPECT_FALSE(u.contains("password_hash")) << u.dump();
    if (u.at("name") == "grace") {
      listed = true;
      EXPECT_EQ(u.at("source"), "registry");
      EXPECT_EQ(u.at("changed_by"), "operator");
    }
    if (u.at("name") == "viewer") {
      EXPECT_EQ(u.at("source"), "configuration");
    }
  }
  EXPECT_TRUE(listed) << users.dump();
  const auto trail = a.get("/api/audit?limit=100").at("entries");
  EXPECT_TRUE(std::any_of(trail.begin(), trail.end(), [](const json& e) {
    return e.at("action") == "user.put" && e.at("subject") == "user grace" && !e.at("details").contains("password");
  })) << trail.dump();

  ASSERT_EQ(b.call("DELETE", "/api/users/grace").status, 200);
  EXPECT_EQ(b.call("DELETE", "/api/users/grace").status, 404);
  std::this_thread::sleep_for(daemon::Auth::kLabUsersFresh + std::chrono::milliseconds(200));
  EXPECT_EQ(sign_in(a, "grace's long password").status, 401);
}
