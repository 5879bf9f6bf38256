// Alarms an operator acknowledges (issue 18, item 1): which events and state changes raise one and
// how serious it is, what clears it, the database keeping raise, clear and acknowledgement (once),
// the API listing, acknowledging (operators only, with their name) and the run's log as RFC 4180
// CSV; end to end with a chamber out of band that suspends a run and clears, an interruption by a
// shutdown, and one found at start-up after a crash.
#include <gtest/gtest.h>

#include <filesystem>
#include <mutex>
#include <vector>

#include "daemon/db/daemon_db.hpp"
#include "daemon/subscribers/alarms.hpp"
#include "service_fixture.hpp"

using namespace imucal;
using namespace imucal::daemontest;
using daemon::AlarmRow;
using daemon::DaemonDb;
using daemon::RunState;

namespace {

json chamber_campaign(const std::string& name, double time_scale) {
  return {{"name", name},
          {"program", "direct-short"},
          {"rate_hz", 50},
          {"seed", 3},
          {"time_scale", time_scale},
          {"truth", noisy_truth()},
          {"estimators", json::array()},
          {"sim_faults", {{{"kind", "chamber_offset"}, {"at_s", 150}, {"duration_s", 20}, {"offset_C", 6}}}}};
}

std::string ack_target(std::int64_t id) { return "/api/alarms/" + std::to_string(id) + "/ack"; }

std::string error_of(const daemon::HttpReply& r) { return json::parse(r.body).value("error", std::string()); }

// The live messages of a daemon without HTTP, as its WebSocket would carry them.
struct Messages {
  std::mutex mutex;
  std::vector<json> list;
  void attach(daemon::Service& s) {
    auto add = [this](const json& m) {
      std::lock_guard lock(mutex);
      list.push_back(m);
    };
    s.sequencer().set_event_listener(add);
    s.api().set_event_listener(add);
  }
  std::vector<json> alarms(const std::string& change) {
    std::lock_guard lock(mutex);
    std::vector<json> out;
    for (const auto& m : list)
      if (m.value("type", "") == "alarm" && m.value("change", "") == change) out.push_back(m.at("alarm"));
    return out;
  }
};

}  // namespace

TEST(Alarms, SeriousEventsRaiseAlarmsOfTheirSeverity) {
  EXPECT_EQ(daemon::alarm_severity_of_event("suspended"), "major");
  EXPECT_EQ(daemon::alarm_severity_of_event("error"), "major");
  EXPECT_EQ(daemon::alarm_severity_of_event("alarm"), "minor");
  for (const char* quiet : {"info", "redo", "resumed", "paused", "homed", "transition"})
    EXPECT_FALSE(daemon::alarm_severity_of_event(quiet).has_value()) << quiet;
}

TEST(Alarms, StateChangesClearWhatEndedAndRaiseAnInterruption) {
  // Running again: the suspension's alarm clears, the others stay active.
  auto t = daemon::alarms_for_transition(RunState::Suspended, RunState::Running, "chamber out of band: 31 °C cleared");
  EXPECT_FALSE(t.clear_all);
  EXPECT_EQ(t.clear_source, "suspended");
  EXPECT_EQ(t.clear_reason, "suspended -> running: chamber out of band: 31 °C cleared");
  EXPECT_FALSE(t.raise_interrupted);
  // The run ends: every alarm of it clears (nothing of it is going on any more).
  for (const RunState end : {RunState::Done, RunState::Failed, RunState::Aborted}) {
    t = daemon::alarms_for_transition(RunState::Running, end, "");
    EXPECT_TRUE(t.clear_all);
    EXPECT_FALSE(t.raise_interrupted);
  }
  // Parked by a shutdown or a crash: cleared, and the interruption is an alarm of its own.
  t = daemon::alarms_for_transition(RunState::Suspended, RunState::Interrupted, "the daemon shut down");
  EXPECT_TRUE(t.clear_all);
  EXPECT_TRUE(t.raise_interrupted);
  // Taken up again (resume) or given up (abort): the interruption has ended.
  EXPECT_TRUE(daemon::alarms_for_transition(RunState::Interrupted, RunState::Queued, "resume by operator").clear_all);
  EXPECT_TRUE(daemon::alarms_for_transition(RunState::Interrupted, RunState::Aborted, "abort by operator").clear_all);
  // Nothing to do on the way into a hold: the suspension's event raises its alarm.
  t = daemon::alarms_for_transition(RunState::Running, RunState::Suspended, "chamber out of band");
  EXPECT_FALSE(t.clear_all || t.clear_source || t.raise_interrupted);
  t = daemon::alarms_for_transition(RunState::Created, RunState::Queued, "start by operator");
  EXPECT_FALSE(t.clear_all || t.clear_source || t.raise_interrupted);
}

TEST(Alarms, TheRunLogIsRfc4180Csv) {
  EXPECT_EQ(daemon::csv_field("plain text"), "plain text");
  EXPECT_EQ(daemon::csv_field("a, b"), "\"a, b\"");
  EXPECT_EQ(daemon::csv_field("say \"hold\""), "\"say \"\"hold\"\"\"");
  EXPECT_EQ(daemon::csv_field("two\r\nlines"), "\"two\r\nlines\"");
  EXPECT_EQ(daemon::csv_field(""), "");
  // Text a spreadsheet would run as a formula is defused; numbers stay numbers.
  EXPECT_EQ(daemon::csv_field("=HYPERLINK(\"x\")"), "\"'=HYPERLINK(\"\"x\"\")\"");
  EXPECT_EQ(daemon::csv_field("@SUM(A1)"), "'@SUM(A1)");
  EXPECT_EQ(daemon::csv_field("-1.5e-3"), "-1.5e-3");
  EXPECT_EQ(daemon::csv_field("+3"), "+3");
  EXPECT_EQ(daemon::csv_field("- table fault"), "'- table fault");

  std::vector<daemon::TransitionRow> transitions = {{1000, RunState::Queued, RunState::Running, "devices free: starting"},
                                                    {3000, RunState::Running, RunState::Suspended, "chamber out of band"}};
  std::vector<daemon::EventRow> events = {{3000, "suspended", 4, 81.25, "chamber out of band: 31 °C, set point 25 °C"},
                                          {2000, "info", std::nullopt, std::nullopt, "simulated bench"}};
  AlarmRow alarm;
  alarm.id = 7;
  alarm.campaign_id = 1;
  alarm.severity = "major";
  alarm.source = "suspended";
  alarm.message = "chamber out of band: 31 °C, set point 25 °C";
  alarm.segment = 4;
  alarm.program_time_s = 81.25;
  alarm.raised_ms = 3000;
  alarm.cleared_ms = 9000;
  alarm.cleared_reason = "suspended -> running: \"chamber\" cleared";
  alarm.acknowledged_by = "alice";
  alarm.acknowledged_ms = 12000;
  const std::string csv = daemon::run_log_csv(transitions, events, {alarm});
  const std::string expected =
      "time,record,kind,severity,segment,program_time_s,message,alarm_id,raised,cleared,cleared_reason,"
      "acknowledged_by,acknowledged\r\n"
      "1970-01-01T00:00:01.000Z,transition,queued -> running,,,,devices free: starting,,,,,,\r\n"
      "1970-01-01T00:00:02.000Z,event,info,,,,simulated bench,,,,,,\r\n"
      "1970-01-01T00:00:03.000Z,transition,running -> suspended,,,,chamber out of band,,,,,,\r\n"
      "1970-01-01T00:00:03.000Z,event,suspended,major,4,81.250,\"chamber out of band: 31 °C, set point 25 °C\",,,,,,\r\n"
      "1970-01-01T00:00:03.000Z,alarm,suspended,major,4,81.250,\"chamber out of band: 31 °C, set point 25 °C\",7,"
      "1970-01-01T00:00:03.000Z,1970-01-01T00:00:09.000Z,\"suspended -> running: \"\"chamber\"\" cleared\",alice,"
      "1970-01-01T00:00:12.000Z\r\n";
  EXPECT_EQ(csv, expected);
}

TEST(Alarms, TheDatabaseKeepsRaiseClearAndOneAcknowledgement) {
  const std::string dir = scratch_dir("alarm-db");
  const std::string path = dir + "/imucald.db";
  std::int64_t campaign = 0, first = 0, second = 0;
  {
    DaemonDb db(path);
    campaign = db.insert_campaign("c", "{}", "direct", 10.0, "test");
    const AlarmRow a = db.raise_alarm(campaign, "major", "suspended", "chamber out of band", 2, 31.5);
    const AlarmRow b = db.raise_alarm(campaign, "minor", "alarm", "recorder queue_high_water", 2, 32.0);
    first = a.id;
    second = b.id;
    EXPECT_EQ(a.campaign_name, "c");
    EXPECT_EQ(a.segment, 2);
    EXPECT_FALSE(a.cleared_ms.has_value());
    EXPECT_GT(a.raised_ms, 0);
    EXPECT_EQ(db.alarms(std::nullopt, false).size(), 2u);

    // Clearing one source leaves the other active.
    const auto cleared = db.clear_alarms(campaign, std::string("suspended"), "suspended -> running");
    ASSERT_EQ(cleared.size(), 1u);
    EXPECT_EQ(cleared[0].id, first);
    EXPECT_EQ(cleared[0].cleared_reason, "suspended -> running");
    EXPECT_TRUE(db.clear_alarms(campaign, std::string("suspended"), "again").empty());  // cleared once
    // Cleared but not acknowledged: still listed.
    EXPECT_EQ(db.alarms(campaign, false).size(), 2u);

    auto [outcome, row] = db.acknowledge_alarm(first, "alice");
    EXPECT_EQ(outcome, DaemonDb::Ack::Acknowledged);
    ASSERT_TRUE(row.has_value());
    EXPECT_EQ(row->acknowledged_by, "alice");
    // A second acknowledgement changes nothing and says who was first.
    auto [again, kept] = db.acknowledge_alarm(first, "bob");
    EXPECT_EQ(again, DaemonDb::Ack::AlreadyAcknowledged);
    ASSERT_TRUE(kept.has_value());
    EXPECT_EQ(kept->acknowledged_by, "alice");
    EXPECT_EQ(kept->acknowledged_ms, row->acknowledged_ms);
    EXPECT_EQ(db.acknowledge_alarm(9999, "alice").first, DaemonDb::Ack::NoSuchAlarm);

    // Cleared and acknowledged: only with `all`. Acknowledged but active: still listed.
    EXPECT_EQ(db.acknowledge_alarm(second, "alice").first, DaemonDb::Ack::Acknowledged);
    const auto open = db.alarms(std::nullopt, false);
    ASSERT_EQ(open.size(), 1u);
    EXPECT_EQ(open[0].id, second);
    EXPECT_EQ(db.alarms(campaign, true).size(), 2u);
    EXPECT_TRUE(db.alarms(campaign + 1, true).empty());
    // The newest ones when limited, oldest first.
    const auto newest = db.alarms(std::nullopt, true, 1);
    ASSERT_EQ(newest.size(), 1u);
    EXPECT_EQ(newest[0].id, second);
  }
  // Kept across opening the database again.
  DaemonDb db(path);
  const auto a = db.alarm(first);
  ASSERT_TRUE(a.has_value());
  EXPECT_EQ(a->acknowledged_by, "alice");
  EXPECT_EQ(a->message, "chamber out of band");
}

TEST(Alarms, AChamberSuspensionIsListedUntilAnOperatorAcknowledgesIt) {
  LocalDaemon d("alarm-api");
  Messages messages;
  messages.attach(*d.service);
  const auto id = d.post_campaign(chamber_campaign("chamber alarm", 0));
  ASSERT_EQ(d.command(id, "start"), 200);
  const json c = d.wait_final(id);
  ASSERT_EQ(c.at("state"), "done") << c.dump();

  // The suspension raised a major alarm; the resume cleared it; nobody has acknowledged it yet.
  const json listed = d.get("/api/alarms");
  ASSERT_EQ(listed.at("alarms").size(), 1u) << listed.dump();
  const json alarm = listed.at("alarms")[0];
  EXPECT_EQ(alarm.at("campaign"), id);
  EXPECT_EQ(alarm.at("campaign_name"), "chamber alarm");
  EXPECT_EQ(alarm.at("severity"), "major");
  EXPECT_EQ(alarm.at("source"), "suspended");
  EXPECT_NE(alarm.at("message").get<std::string>().find("chamber out of band"), std::string::npos) << alarm.dump();
  EXPECT_FALSE(alarm.at("active").get<bool>());
  EXPECT_TRUE(alarm.at("cleared").is_string());
  EXPECT_NE(alarm.at("cleared_reason").get<std::string>().find("suspended -> running"), std::string::npos) << alarm.dump();
  EXPECT_LE(alarm.at("raised").get<std::string>(), alarm.at("cleared").get<std::string>());
  EXPECT_TRUE(alarm.at("acknowledged_by").is_null());
  EXPECT_TRUE(alarm.at("acknowledged").is_null());
  // The campaign's record holds it too.
  ASSERT_EQ(c.at("alarms").size(), 1u);
  EXPECT_EQ(c.at("alarms")[0].at("id"), alarm.at("id"));
  // The live stream said so as it happened.
  ASSERT_EQ(messages.alarms("raised").size(), 1u);
  EXPECT_TRUE(messages.alarms("raised")[0].at("active").get<bool>());
  ASSERT_EQ(messages.alarms("cleared").size(), 1u);
  EXPECT_EQ(messages.alarms("cleared")[0].at("id"), alarm.at("id"));

  // A viewer sees it and cannot acknowledge it.
  const std::int64_t alarm_id = alarm.at("id");
  const auto by_viewer = d.call("POST", ack_target(alarm_id), "", kViewerToken);
  EXPECT_EQ(by_viewer.status, 403);
  EXPECT_EQ(error_of(by_viewer), "operator role required");
  EXPECT_EQ(json::parse(d.call("GET", "/api/alarms", "", kViewerToken).body).at("alarms").size(), 1u);

  // The operator acknowledges it: their name and the time are kept, and it leaves the list.
  const auto acked = d.call("POST", ack_target(alarm_id));
  ASSERT_EQ(acked.status, 200) << acked.body;
  const json a = json::parse(acked.body);
  EXPECT_EQ(a.at("acknowledged_by"), "operator");
  EXPECT_TRUE(a.at("acknowledged").is_string());
  ASSERT_EQ(messages.alarms("acknowledged").size(), 1u);
  EXPECT_EQ(messages.alarms("acknowledged")[0].at("acknowledged_by"), "operator");
  EXPECT_TRUE(d.get("/api/alarms").at("alarms").empty());
  const json all = d.get("/api/alarms?all=1&campaign=" + std::to_string(id));
  ASSERT_EQ(all.at("alarms").size(), 1u);
  EXPECT_EQ(all.at("alarms")[0].at("acknowledged_by"), "operator");

  // Once only, and clear words for what is wrong.
  const auto twice = d.call("POST", ack_target(alarm_id));
  EXPECT_EQ(twice.status, 409);
  EXPECT_NE(error_of(twice).find("was already acknowledged by operator at "), std::string::npos) << twice.body;
  EXPECT_EQ(d.call("POST", ack_target(9999)).status, 404);
  EXPECT_EQ(error_of(d.call("POST", ack_target(9999))), "no alarm 9999");
  EXPECT_EQ(d.call("POST", "/api/alarms/abc/ack").status, 404);
  EXPECT_EQ(d.call("GET", ack_target(alarm_id)).status, 405);
  EXPECT_EQ(d.call("GET", "/api/alarms?campaign=abc").status, 400);
  EXPECT_EQ(d.call("GET", "/api/alarms?campaign=9999").status, 404);
  EXPECT_EQ(d.call("GET", "/api/alarms?all=yes").status, 400);
  EXPECT_EQ(d.call("GET", "/api/alarms", "", "").status, 401);

  // The run's log as CSV: its transitions, events and the alarm with raise, clear and acknowledgement.
  const auto csv = d.call("GET", "/api/campaigns/" + std::to_string(id) + "/events.csv", "", kViewerToken);
  ASSERT_EQ(csv.status, 200) << csv.body;
  EXPECT_EQ(csv.content_type, "text/csv; charset=utf-8");
  EXPECT_EQ(csv.body.rfind("time,record,kind,severity,segment,program_time_s,message,alarm_id,raised,cleared,", 0), 0u);
  EXPECT_NE(csv.body.find(",transition,running -> suspended,"), std::string::npos);
  EXPECT_NE(csv.body.find(",event,suspended,major,"), std::string::npos);
  const auto alarm_line = csv.body.find(",alarm,suspended,major,");
  ASSERT_NE(alarm_line, std::string::npos) << csv.body;
  const std::string line = csv.body.substr(alarm_line, csv.body.find("\r\n", alarm_line) - alarm_line);
  EXPECT_NE(line.find(alarm.at("raised").get<std::string>()), std::string::npos) << line;
  EXPECT_NE(line.find(alarm.at("cleared").get<std::string>()), std::string::npos) << line;
  EXPECT_NE(line.find(",operator," + a.at("acknowledged").get<std::string>()), std::string::npos) << line;
  bool disposition = false;
  for (const auto& [k, v] : csv.headers)
    if (k == "Content-Disposition") disposition = v.find("campaign-" + std::to_string(id) + "-events.csv") != std::string::npos;
  EXPECT_TRUE(disposition);
  EXPECT_EQ(d.call("GET", "/api/campaigns/9999/events.csv").status, 404);
}

TEST(Alarms, AnInterruptionIsAnAlarmUntilTheRunIsTakenUp) {
  LocalDaemon d("alarm-interrupted");
  const auto id = d.post_campaign(chamber_campaign("interrupted", 2));
  ASSERT_EQ(d.command(id, "start"), 200);
  d.wait_for(id, [](const json& c) { return c.at("program_time_s").get<double>() > 1.0; });
  d.service->stop();  // parks the run: interrupted
  const json alarms = d.get("/api/alarms");
  ASSERT_EQ(alarms.at("alarms").size(), 1u) << alarms.dump();
  const json a = alarms.at("alarms")[0];
  EXPECT_EQ(a.at("source"), "interrupted");
  EXPECT_EQ(a.at("severity"), "major");
  EXPECT_TRUE(a.at("active").get<bool>());
  EXPECT_NE(a.at("message").get<std::string>().find("the daemon shut down"), std::string::npos) << a.dump();

  // A new daemon on the same data: the alarm is still there; resuming the run clears it.
  d.service.reset();
  d.service = std::make_unique<daemon::Service>(d.config);
  d.service->start(false);
  ASSERT_EQ(d.get("/api/alarms").at("alarms").size(), 1u);
  ASSERT_EQ(d.command(id, "resume"), 200);
  ASSERT_EQ(d.command(id, "abort"), 200);
  d.wait_final(id);
  const json after = d.get("/api/alarms?all=1");
  ASSERT_GE(after.at("alarms").size(), 1u);
  const json interrupted = after.at("alarms").back();  // newest first: the first one raised is last
  EXPECT_EQ(interrupted.at("id"), a.at("id"));
  EXPECT_FALSE(interrupted.at("active").get<bool>());
  EXPECT_NE(interrupted.at("cleared_reason").get<std::string>().find("interrupted -> queued"), std::string::npos)
      << interrupted.dump();
}

TEST(Alarms, ARunFoundActiveAfterACrashRaisesAnInterruption) {
  const std::string dir = scratch_dir("alarm-crash");
  std::int64_t id = 0;
  {
    // What a crash leaves: a run recorded as running, with its suspension's alarm still active.
    DaemonDb db(dir + "/imucald.db");
    id = db.insert_campaign("crashed", "{}", "direct", 10.0, "test");
    ASSERT_TRUE(db.set_state(id, RunState::Queued, "start"));
    ASSERT_TRUE(db.set_state(id, RunState::Running, "devices free"));
    ASSERT_TRUE(db.set_state(id, RunState::Suspended, "chamber out of band"));
    db.raise_alarm(id, "major", "suspended", "chamber out of band", 1, 12.0);
  }
  daemon::Service service(test_config(dir));
  service.start(false);
  daemon::ApiRequest r;
  r.method = "GET";
  r.target = "/api/alarms";
  r.authorization = std::string("Bearer ") + kOperatorToken;
  const json listed = json::parse(service.api().handle(r).body);
  ASSERT_EQ(listed.at("alarms").size(), 2u) << listed.dump();
  const json interrupted = listed.at("alarms")[0];  // newest first
  EXPECT_EQ(interrupted.at("source"), "interrupted");
  EXPECT_TRUE(interrupted.at("active").get<bool>());
  EXPECT_NE(interrupted.at("message").get<std::string>().find("crash or power loss"), std::string::npos);
  const json suspension = listed.at("alarms")[1];
  EXPECT_EQ(suspension.at("source"), "suspended");
  EXPECT_FALSE(suspension.at("active").get<bool>());  // its run is parked: the hold is over
  EXPECT_NE(suspension.at("cleared_reason").get<std::string>().find("suspended -> interrupted"), std::string::npos);
  service.stop();
}
