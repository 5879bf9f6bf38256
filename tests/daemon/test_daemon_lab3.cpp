// Issue 38's acceptance: a lab of three stands (three imucald on the simulated bench, each with its
// own data directory and stand name) on one PostgreSQL registry (a private server of this test,
// tests/postgres_server.hpp), driven through their HTTP APIs as operators would:
//  (a) a unit calibrated on two stands has one history, read alike from any of the three;
//  (b) the three stands issuing 20 certificates each at the same time get 60 distinct numbers, in
//      the order of issue, none lost;
//  (c) the server stopped for 30 s in the middle of a campaign: the run ends done, the stand says
//      the registry is unreachable meanwhile, and each of its registry writes arrives exactly once.
// Each test is its own process under ctest (gtest_discover_tests), with its own server. Every wait
// has a generous deadline and nothing is timed but the 30 s outage: the machine may be loaded.
#include <gtest/gtest.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <filesystem>
#include <fstream>
#include <functional>
#include <iostream>
#include <iterator>
#include <map>
#include <memory>
#include <optional>
#include <set>
#include <string>
#include <thread>
#include <vector>

#include "daemon/db/audit_chain.hpp"
#include "daemon/registry/calibrations.hpp"
#include "daemon/registry/postgres_registry.hpp"
#include "service_fixture.hpp"
#include "storage/postgres.hpp"
#include "tests/postgres_server.hpp"

using namespace imucal;
using namespace imucal::daemontest;

namespace {

constexpr const char* kPartNumber = "PN-LAB3";

// A stand: an imucald with its HTTP server (port 0: any free one) on the lab's registry, and an
// operator's client of that server.
struct Stand {
  Stand(const std::string& stand_name, const std::string& conninfo, double heartbeat_s)
      : imucald("lab3-" + stand_name, true,
               [&](daemon::DaemonConfig& c) {
                 c.registry.postgresql = conninfo;
                 c.registry.stand = stand_name;
                 c.registry.heartbeat_s = heartbeat_s;
                 c.certificates.prefix = "LAB";
               }),
        client{imucald.service->port(), kOperatorToken},
        name(stand_name) {}
  LocalDaemon imucald;
  Client client;
  std::string name;
};

json calibration(const std::string& name, const std::string& serial, double time_scale = 0.0) {
  return direct_short_calibration(name, {{"serial", serial}, {"part_number", kPartNumber}}, time_scale);
}

bool poll(const std::function<bool()>& done, double timeout_s) {
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::duration<double>(timeout_s);
  while (!done()) {
    if (std::chrono::steady_clock::now() > deadline) return false;
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
  }
  return true;
}

json registry_status(const Stand& s) { return s.client.get_json("/api/status").value("registry", json()); }

// A campaign run to its end; its final row as GET /api/campaigns/{id} shows it.
json run_to_end(Stand& s, std::int64_t id) {
  const json last = s.imucald.wait_final(id, 900.0);
  EXPECT_EQ(last.value("state", ""), "done") << s.name << " campaign " << id << ": " << last.dump().substr(0, 2000);
  return last;
}

// ---- What the registry's server holds, read straight from it ----

struct IssuedRecord {
  std::int64_t sequence = 0;
  std::string number, stand;
  std::int64_t campaign_id = 0, issued_ms = 0;
  std::optional<std::string> supersedes, superseded_by;
  std::string reason;
};

std::vector<IssuedRecord> issued_records(const std::string& conninfo) {
  storage::pg::Connection pg(conninfo, "test");
  const auto r = pg.exec(
      "SELECT sequence, number, stand, campaign_id, issued_ms, supersedes, superseded_by, reason "
      "FROM issued_certificate ORDER BY sequence");
  std::vector<IssuedRecord> out;
  for (int i = 0; i < r.rows(); ++i)
    out.push_back({r.int64(i, 0), r.text(i, 1), r.text(i, 2), r.int64(i, 3), r.int64(i, 4), r.optional_text(i, 5),
                   r.optional_text(i, 6), r.text(i, 7)});
  return out;
}

struct AuditRecord {
  std::int64_t seq = 0;
  std::string stand;
  std::int64_t t_ms = 0;
  std::string action, subject;
  json details;
};

std::vector<AuditRecord> audit_records(const std::string& conninfo) {
  storage::pg::Connection pg(conninfo, "test");
  const auto r = pg.exec("SELECT seq, stand, t_ms, action, subject, details_json FROM audit ORDER BY seq");
  std::vector<AuditRecord> out;
  for (int i = 0; i < r.rows(); ++i)
    out.push_back({r.int64(i, 0), r.text(i, 1), r.int64(i, 2), r.text(i, 3), r.text(i, 4),
                   json::parse(r.text(i, 5), nullptr, false)});
  return out;
}

// The trail's hashes, links and head hold (audit_chain.hpp), as `imucal audit verify` checks them.
void expect_intact_chain(const std::string& conninfo) {
  daemon::PostgresRegistry registry(conninfo, "test");
  const daemon::AuditCheck check = daemon::check_audit_chain(registry.audit_chain());
  EXPECT_TRUE(check.ok()) << check.message;
}

// An audit entry as a line to compare: what, about what, and the part of its details that tells
// two entries of one kind apart (a transition's states and reason, a command's name).
std::string audit_key(const std::string& action, const std::string& subject, const json& details) {
  std::string key = action + " | " + subject;
  if (action == "campaign.transition")
    key += " | " + details.value("from", std::string("?")) + " -> " + details.value("to", std::string("?")) + ": " +
           details.value("reason", std::string());
  if (action == "campaign.command") key += " | " + details.value("command", std::string("?"));
  return key;
}

// The entries in `got` and not in `want` and the other way round, counted: a duplicate shows as one
// entry too many.
std::string multiset_difference(std::vector<std::string> got, std::vector<std::string> want) {
  std::sort(got.begin(), got.end());
  std::sort(want.begin(), want.end());
  std::vector<std::string> extra, missing;
  std::set_difference(got.begin(), got.end(), want.begin(), want.end(), std::back_inserter(extra));
  std::set_difference(want.begin(), want.end(), got.begin(), got.end(), std::back_inserter(missing));
  std::string out;
  for (const auto& e : extra) out += "\n  in the registry once too often (or never made by the stand): " + e;
  for (const auto& m : missing) out += "\n  made by the stand, missing from the registry: " + m;
  return out;
}

}  // namespace

// Three stands on one private PostgreSQL server, a fresh registry database for each test.
class ThreeStandLab : public ::testing::Test {
 protected:
  static imucaltest::PostgresServer& server() { return imucaltest::shared_postgres_server(); }
  void SetUp() override {
    IMUCALTEST_FRESH_POSTGRES_DATABASE(conninfo_, "lab3");
    for (const char* name : {"stand-a", "stand-b", "stand-c"})
      stands_.push_back(std::make_unique<Stand>(name, conninfo_, heartbeat_s()));
    for (const auto& s : stands_)
      ASSERT_TRUE(poll([&] { return registry_status(*s).value("reachable", false); }, 60.0))
          << s->name << " never reached the registry: " << registry_status(*s).dump();
  }
  void TearDown() override {
    stands_.clear();  // the stands stop before anything of the server goes
    // The server is the executable's: never left stopped by a test that failed in its outage.
    if (server().skip_reason().empty()) {
      EXPECT_TRUE(server().start_again());
    }
  }
  Stand& stand(std::size_t i) { return *stands_.at(i); }
  // The stands beat often: one notices the server gone, and back, within a few seconds.
  virtual double heartbeat_s() const { return 0.2; }

  std::string conninfo_;
  std::vector<std::unique_ptr<Stand>> stands_;
};

// (a) One unit (one serial) calibrated on stand a, then on stand b: any of the three stands lists
// both calibrations as the unit's history, each naming the stand that made it, oldest first.
TEST_F(ThreeStandLab, AUnitCalibratedOnTwoStandsHasOneHistorySeenAlikeFromEveryStand) {
  const std::string serial = "FOG-LAB3-1";
  const std::int64_t on_a = stand(0).client.post_and_start(calibration("first on a", serial));
  ASSERT_GT(on_a, 0);
  run_to_end(stand(0), on_a);
  const std::int64_t on_b = stand(1).client.post_and_start(calibration("again on b", serial));
  ASSERT_GT(on_b, 0);
  run_to_end(stand(1), on_b);

  for (std::size_t i = 0; i < 3; ++i) {
    json unit;
    // Each run's calibration is recorded by its stand as its run ends: asked until both are there.
    poll([&] {
      unit = stand(i).client.get_json("/api/imus/" + serial);
      return unit.contains("calibrations") && unit.at("calibrations").size() == 2 &&
             unit.at("calibrations")[1].value("state", "") == "done";
    }, 60.0);
    ASSERT_TRUE(unit.contains("calibrations")) << stand(i).name << ": " << unit.dump().substr(0, 2000);
    const json& history = unit.at("calibrations");
    ASSERT_EQ(history.size(), 2U) << stand(i).name << ": " << unit.dump().substr(0, 2000);
    EXPECT_EQ(history[0].at("stand"), "stand-a") << stand(i).name;
    EXPECT_EQ(history[0].at("campaign_id"), on_a) << stand(i).name;
    EXPECT_EQ(history[0].at("name"), "first on a") << stand(i).name;
    EXPECT_EQ(history[1].at("stand"), "stand-b") << stand(i).name;
    EXPECT_EQ(history[1].at("campaign_id"), on_b) << stand(i).name;
    EXPECT_EQ(history[1].at("name"), "again on b") << stand(i).name;
    EXPECT_LE(history[0].at("date").get<std::string>(), history[1].at("date").get<std::string>()) << "oldest first";
    for (const json& c : history) {
      EXPECT_EQ(c.at("state"), "done") << c.dump().substr(0, 400);
      EXPECT_TRUE(c.at("counts").get<bool>()) << c.dump().substr(0, 400);
      EXPECT_TRUE(c.at("model").is_object()) << "a history shows each calibration's model";
    }
    EXPECT_EQ(unit.at("calibrations_counted"), 2) << stand(i).name;
  }
  // Stand c ran nothing: what it showed is the registry's, not its own.
  EXPECT_EQ(stand(2).client.get_json("/api/campaigns").at("campaigns").size(), 0U);
}

namespace {

// Limits for the lab's part number whose bound is `n`-th of a series no two documents share: every
// document put changes what each certificate of the part states (the bound is in its verdict), so
// each put makes its stand supersede its certificate once, whatever another stand put meanwhile.
json limits_document(int n) {
  const json bound = {{"max_abs", 10.0 + 0.01 * n}};
  return {{"format", "imucal-limits/1"}, {"part_numbers", {{kPartNumber, {{"gyro.bias_dph", bound}}}}}};
}

// Each stand's thread puts `each` limits documents through its stand's HTTP API, all three at
// once; the statuses of the puts that failed, by stand.
std::vector<std::string> put_limits_at_once(std::vector<Stand*> stands, int each) {
  std::atomic<int> series{0};
  std::atomic<bool> go{false};
  std::vector<std::string> failures(stands.size());
  std::vector<std::thread> threads;
  for (std::size_t i = 0; i < stands.size(); ++i) {
    threads.emplace_back([&, i] {
      while (!go) std::this_thread::yield();  // the three start together
      for (int k = 0; k < each; ++k) {
        const HttpResult r = http_request(stands[i]->client.port, "PUT", "/api/limits",
                                          limits_document(++series).dump(), stands[i]->client.auth());
        if (r.status != 200) failures[i] += " " + std::to_string(r.status) + ": " + r.body.substr(0, 300);
      }
    });
  }
  go = true;
  for (auto& t : threads) t.join();
  return failures;
}

}  // namespace

// The stands of (b) beat once an hour: each beat also follows the lab's limits, reissuing the
// stand's certificates under the limits another stand put (production/limits_follower.hpp), and
// (b) counts each stand's issues of its own puts, 20, not how many beats fell among them.
class ThreeStandLabPuttingLimits : public ThreeStandLab {
 protected:
  double heartbeat_s() const override { return 3600.0; }
};

// (b) Each stand has a certified run; then the three stands' HTTP APIs are hit at once, 20 times
// each, with new acceptance limits: each put supersedes that stand's certificate (the cheapest
// honest issue: a new number from the registry's sequence, a new frozen content, the audit entry;
// a run to its end costs seconds). 60 issues at once get 60 distinct numbers with the 3 of the
// runs' ends, in the order they were issued by the times the registry and the audit trail
// recorded, none lost: no gap in the sequence, every one audited once.
TEST_F(ThreeStandLabPuttingLimits, SixtyCertificatesIssuedAtOnceOnThreeStandsGetDistinctNumbersInTheOrderOfIssue) {
  constexpr int kEach = 20;
  std::vector<Stand*> all;
  std::map<std::string, std::int64_t> run_of;  // stand -> its certified campaign
  for (std::size_t i = 0; i < 3; ++i) {
    all.push_back(&stand(i));
    run_of[stand(i).name] = stand(i).client.post_and_start(calibration("run on " + stand(i).name, "FOG-LAB3-" + std::to_string(i)));
    ASSERT_GT(run_of[stand(i).name], 0);
  }
  for (Stand* s : all) {
    run_to_end(*s, run_of[s->name]);
    // Issued at the run's end (asked until the run's last subscriber has issued it).
    ASSERT_TRUE(poll([&] { return s->client.get("/api/campaigns/" + std::to_string(run_of[s->name]) + "/certificate").status == 200; }, 60.0));
  }

  const auto failures = put_limits_at_once(all, kEach);
  for (std::size_t i = 0; i < all.size(); ++i) EXPECT_EQ(failures[i], "") << all[i]->name;

  // Each stand's certificate: 1 at the run's end and 20 superseding ones, each naming the one
  // before; the last in force.
  for (Stand* s : all) {
    const json c = s->client.get_json("/api/campaigns/" + std::to_string(run_of[s->name]) + "/certificate");
    ASSERT_TRUE(c.contains("history")) << c.dump().substr(0, 1000);
    EXPECT_EQ(c.at("history").size(), static_cast<std::size_t>(kEach + 1)) << s->name;
    EXPECT_TRUE(c.at("superseded_by").is_null()) << s->name;
    // A number is the lab's: another stand finds it.
    const Stand* other = s == all[0] ? all[1] : all[0];
    EXPECT_EQ(other->client.get("/api/certificates/" + c.at("number").get<std::string>()).status, 200);
  }

  const auto issued = issued_records(conninfo_);
  ASSERT_EQ(issued.size(), static_cast<std::size_t>(3 * (kEach + 1)));
  std::set<std::string> numbers;
  std::map<std::string, std::vector<const IssuedRecord*>> by_stand;
  for (std::size_t i = 0; i < issued.size(); ++i) {
    const IssuedRecord& c = issued[i];
    numbers.insert(c.number);
    by_stand[c.stand].push_back(&c);
    // None lost: the sequence has no gap (no number taken and not recorded).
    EXPECT_EQ(c.sequence, static_cast<std::int64_t>(i + 1)) << c.number;
    // In the order of issue: a later number was never issued before an earlier one (two issues
    // can share a millisecond).
    if (i > 0) {
      EXPECT_LE(issued[i - 1].issued_ms, c.issued_ms)
          << issued[i - 1].number << " (" << issued[i - 1].stand << ") was issued after " << c.number << " ("
          << c.stand << "): " << issued[i - 1].issued_ms << " > " << c.issued_ms << " ms";
    }
  }
  EXPECT_EQ(numbers.size(), issued.size()) << "a number issued twice";
  for (Stand* s : all) {
    const auto& mine = by_stand[s->name];
    ASSERT_EQ(mine.size(), static_cast<std::size_t>(kEach + 1)) << s->name;
    EXPECT_EQ(mine[0]->reason, "the run ended");
    for (std::size_t k = 0; k < mine.size(); ++k) {
      EXPECT_EQ(mine[k]->campaign_id, run_of[s->name]);
      if (k == 0) continue;
      EXPECT_EQ(mine[k]->supersedes.value_or(""), mine[k - 1]->number) << s->name;
      EXPECT_EQ(mine[k - 1]->superseded_by.value_or(""), mine[k]->number) << s->name;
      EXPECT_NE(mine[k]->reason.find("acceptance limits changed"), std::string::npos) << mine[k]->reason;
    }
  }

  // The audit trail: one chain; each number issued once, at the time its certificate states, and
  // each stand's in the order of their numbers; 60 supersessions, 60 limits put.
  const auto trail = audit_records(conninfo_);
  std::map<std::string, const IssuedRecord*> record_of;
  for (const auto& c : issued) record_of[c.number] = &c;
  std::map<std::string, int> audited;
  std::map<std::string, std::int64_t> last_sequence_of;  // stand -> its last certificate.issued
  int superseded = 0, limits_put = 0;
  for (const AuditRecord& e : trail) {
    superseded += e.action == "certificate.superseded";
    limits_put += e.action == "limits.replaced";
    if (e.action != "certificate.issued") continue;
    ++audited[e.subject];
    ASSERT_TRUE(record_of.contains(e.subject)) << "an audited certificate the registry does not hold: " << e.subject;
    const IssuedRecord& c = *record_of[e.subject];
    EXPECT_EQ(e.stand, c.stand) << e.subject;
    EXPECT_EQ(e.t_ms, c.issued_ms) << e.subject << ": audited at another time than it states it was issued";
    EXPECT_LT(last_sequence_of[e.stand], c.sequence) << e.stand << " audited " << e.subject << " after its number "
                                                     << last_sequence_of[e.stand];
    last_sequence_of[e.stand] = c.sequence;
  }
  for (const auto& n : numbers) EXPECT_EQ(audited[n], 1) << n << " audited " << audited[n] << " times";
  EXPECT_EQ(superseded, 3 * kEach);
  EXPECT_EQ(limits_put, 3 * kEach);
  expect_intact_chain(conninfo_);
}

namespace {

// The program's length in seconds, as POST /api/campaigns/validate states it.
double program_seconds(const Stand& s, const json& campaign) {
  const HttpResult r = s.client.post("/api/campaigns/validate", campaign.dump());
  EXPECT_EQ(r.status, 200) << r.body;
  return r.json_body().value("duration_s", 0.0);
}

// Every write the stand journaled while the server was away (at least the `waited` its status
// showed) was applied on the server exactly once: the keys of the stand's writes (the stand, its
// journal, the write's number; every write of this process is keyed, journaled or not) recorded
// once for each number from the first, none missing between, nothing left waiting or refused.
void expect_journal_applied_once(const Stand& s, const std::string& conninfo, std::int64_t waited) {
  const std::string journal = s.imucald.config.data_dir + "/registry-journal.jsonl";
  std::ifstream in(journal);
  std::vector<std::string> lines;
  for (std::string line; std::getline(in, line);)
    if (!line.empty()) lines.push_back(line);
  ASSERT_EQ(lines.size(), 1U) << "writes still wait in " << journal << ": " << lines.size() - 1;
  const json header = json::parse(lines[0], nullptr, false);
  ASSERT_TRUE(header.is_object()) << lines[0];
  const std::int64_t journaled = header.value("next_seq", std::int64_t{1}) - 1;
  EXPECT_GE(journaled, waited);
  EXPECT_FALSE(std::filesystem::exists(s.imucald.config.data_dir + "/registry-journal-refused.jsonl"))
      << "the server refused a journaled write at its replay";
  storage::pg::Connection pg(conninfo, "test");
  const auto applied =
      pg.exec("SELECT journal, seq FROM registry_journal_applied WHERE stand = $1 ORDER BY journal, seq", {s.name});
  ASSERT_GE(applied.rows(), journaled);
  for (int i = 0; i < applied.rows(); ++i) {
    EXPECT_EQ(applied.text(i, 0), applied.text(0, 0)) << "one process, one journal of keys";
    EXPECT_EQ(applied.int64(i, 1), i + 1);
  }
  std::cout << "[ lab      ] " << s.name << ": " << journaled << " registry writes journaled while the server was away ("
            << waited << " waiting when it returned), each applied once\n";
}

// The campaign's transitions as the stand's own database recorded them, in order, as audit keys
// (its creation is no transition of the run: it is audited as campaign.created).
std::vector<std::string> recorded_transitions(const Stand& s, std::int64_t id) {
  const json campaign = s.client.get_json("/api/campaigns/" + std::to_string(id));
  std::vector<std::string> out;
  if (!campaign.contains("transitions")) {
    ADD_FAILURE() << "campaign " << id << " of " << s.name << ": " << campaign.dump().substr(0, 1000);
    return out;
  }
  for (const json& t : campaign.at("transitions"))
    if (!t.at("from").is_null()) out.push_back(audit_key("campaign.transition", "campaign " + std::to_string(id), t));
  return out;
}

// The audit entries the stand made, by its own account: its start, each campaign's creation, the
// operator's commands (`commands`: campaign -> the commands given, in order), each transition its
// own database recorded, and each certificate the registry holds of it.
std::vector<std::string> audit_made_by(const Stand& s, const std::map<std::int64_t, std::vector<std::string>>& commands,
                                       const std::vector<IssuedRecord>& certificates) {
  std::vector<std::string> made = {audit_key("service.started", "imucald", {})};
  for (const auto& [id, given] : commands) {
    const std::string subject = "campaign " + std::to_string(id);
    made.push_back(audit_key("campaign.created", subject, {}));
    for (const auto& command : given) made.push_back(audit_key("campaign.command", subject, {{"command", command}}));
    const std::vector<std::string> transitions = recorded_transitions(s, id);
    made.insert(made.end(), transitions.begin(), transitions.end());
  }
  for (const IssuedRecord& c : certificates)
    if (c.stand == s.name) made.push_back(audit_key("certificate.issued", c.number, {}));
  return made;
}

// The stand's audit entries on the server are the ones it made, each once, a campaign's
// transitions in the order its database recorded them; the chain holds.
void expect_audit_as_made(const Stand& s, const std::string& conninfo,
                          const std::map<std::int64_t, std::vector<std::string>>& commands) {
  std::vector<std::string> arrived;
  std::map<std::string, std::vector<std::string>> transitions_arrived;  // subject -> in chain order
  const std::vector<AuditRecord> trail = audit_records(conninfo);
  for (const AuditRecord& e : trail) {
    if (e.stand != s.name) continue;
    arrived.push_back(audit_key(e.action, e.subject, e.details));
    if (e.action == "campaign.transition") transitions_arrived[e.subject].push_back(arrived.back());
  }
  EXPECT_EQ(multiset_difference(arrived, audit_made_by(s, commands, issued_records(conninfo))), "");
  for (const auto& [id, given] : commands) {
    const std::string subject = "campaign " + std::to_string(id);
    EXPECT_EQ(transitions_arrived[subject], recorded_transitions(s, id)) << subject << "'s transitions arrived out of order";
  }
  expect_intact_chain(conninfo);
}

// The server's calibration rows of the stand are its campaigns' rows as its database has them now
// (the last record of each replaced the earlier ones, none arrived stale after a newer one).
void expect_calibrations_as_recorded(Stand& s, const std::string& conninfo, const std::vector<std::int64_t>& ids) {
  storage::pg::Connection pg(conninfo, "test");
  const auto r = pg.exec("SELECT campaign_id, row_json FROM calibration WHERE stand = $1 ORDER BY campaign_id", {s.name});
  ASSERT_EQ(r.rows(), static_cast<int>(ids.size()));
  for (int i = 0; i < r.rows(); ++i) {
    const std::int64_t id = r.int64(i, 0);
    EXPECT_EQ(id, ids.at(static_cast<std::size_t>(i)));
    const auto row = s.imucald.service->db().campaign(id);
    ASSERT_TRUE(row.has_value()) << id;
    EXPECT_EQ(json::parse(r.text(i, 1)), json::parse(daemon::campaign_row_json(*row))) << "campaign " << id;
  }
}

}  // namespace

// (c) The lab's server stopped for 30 s while stand c runs a campaign (about 45 s of wall clock at
// its time scale), an operator pausing and resuming it and queueing the next meanwhile, then
// started again: the run ends done, the stand's status said the registry was unreachable with
// writes waiting, and each write the stand made arrived exactly once (its audit entries, the
// units' calibration rows, the run's certificate), the journaled ones with the time they happened.
TEST_F(ThreeStandLab, TheServerAwayThirtySecondsMidCampaignLosesNoWriteOfTheStandAndRepeatsNone) {
  Stand& s = stand(2);
  json campaign = calibration("through the outage", "FOG-LAB3-C");
  const double seconds = program_seconds(s, campaign);
  ASSERT_GT(seconds, 0.0);
  campaign["time_scale"] = seconds / 45.0;
  const std::int64_t x = s.client.post_and_start(campaign);
  ASSERT_GT(x, 0);
  const std::string x_target = "/api/campaigns/" + std::to_string(x);
  s.client.wait_for(x, [](const json& c) { return c.value("state", "") == "running" && c.value("progress", 0.0) > 0.01; }, 120.0);

  ASSERT_TRUE(server().stop_for_a_while());
  const auto stopped = std::chrono::steady_clock::now();
  const std::int64_t stopped_ms = daemon::now_unix_ms();
  json away;
  EXPECT_TRUE(poll([&] { away = registry_status(s); return !away.value("reachable", true); }, 60.0)) << away.dump();
  // An operator meanwhile: each command, transition and creation is a registry write to journal.
  ASSERT_EQ(s.client.post(x_target + "/pause").status, 200);
  s.client.wait_state(x, "paused", 120.0);
  ASSERT_EQ(s.client.post(x_target + "/resume").status, 200);
  s.client.wait_state(x, "running", 120.0);
  const std::int64_t y = s.client.post_and_start(calibration("queued while away", "FOG-LAB3-C"));
  ASSERT_GT(y, 0);
  EXPECT_EQ(s.client.get_json("/api/campaigns/" + std::to_string(y)).value("state", ""), "queued");

  std::this_thread::sleep_until(stopped + std::chrono::seconds(30));
  away = registry_status(s);
  EXPECT_FALSE(away.value("reachable", true)) << away.dump();
  const std::int64_t waiting = away.value("pending_writes", std::int64_t{0});
  EXPECT_GT(waiting, 0) << away.dump();
  ASSERT_EQ(s.client.get_json(x_target).value("state", ""), "running") << "the campaign must outlast the outage";
  const std::int64_t restarted_ms = daemon::now_unix_ms();
  ASSERT_TRUE(server().start_again());

  run_to_end(s, x);
  run_to_end(s, y);
  json back;
  EXPECT_TRUE(poll([&] {
    back = registry_status(s);
    return back.value("reachable", false) && back.value("pending_writes", -1) == 0;
  }, 120.0)) << back.dump();
  // Each run's certificate, issued at its end with the server back: once each, as the stand reads it.
  std::vector<IssuedRecord> certificates;
  const std::vector<IssuedRecord> issued = issued_records(conninfo_);
  for (const auto& c : issued)
    if (c.stand == s.name) certificates.push_back(c);
  ASSERT_EQ(certificates.size(), 2U);
  const std::map<std::int64_t, const IssuedRecord*> certificate_of = {{x, &certificates[0]}, {y, &certificates[1]}};
  for (const auto& [id, c] : certificate_of) {
    EXPECT_EQ(c->campaign_id, id);
    EXPECT_EQ(c->reason, "the run ended");
    EXPECT_EQ(s.client.get_json("/api/campaigns/" + std::to_string(id) + "/certificate").value("number", ""), c->number);
  }

  expect_journal_applied_once(s, conninfo_, waiting);
  expect_audit_as_made(s, conninfo_, {{x, {"start", "pause", "resume"}}, {y, {"start"}}});
  expect_calibrations_as_recorded(s, conninfo_, {x, y});
  // The journaled entries kept the time they happened, not the time of their replay.
  const std::vector<AuditRecord> trail = audit_records(conninfo_);
  for (const AuditRecord& e : trail)
    if (e.stand == s.name && e.action == "campaign.command" && e.details.value("command", "") == "pause") {
      EXPECT_GE(e.t_ms, stopped_ms);
      EXPECT_LE(e.t_ms, restarted_ms);
    }
}
