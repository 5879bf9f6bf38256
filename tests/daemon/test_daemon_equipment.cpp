// The reference equipment a certificate states (issue 35, deliverable 4): one rule for which
// instrument is overdue or due soon, a start refused for an overdue instrument until an operator
// overrides it with a reason, the override stated on the run's certificate, and the same rule in
// `imucal campaign run`.
#include <gtest/gtest.h>

#include <algorithm>
#include <filesystem>
#include <fstream>
#include <regex>

#include "certificate_fixture.hpp"
#include "core/earth.hpp"
#include "core/expect_value.hpp"
#include "daemon/production/certificates.hpp"
#include "signing/signing.hpp"

using namespace imucal;
using namespace imucal::daemontest;

// Issue 35, deliverable 4: the one rule for which instrument is overdue or due soon on a day, at
// the day boundaries; the start check, the certificate and the live page all judge with it.
TEST(ReferenceEquipment, OneRuleJudgesTheDueDatesAtTheDayBoundaries) {
  const std::int64_t due = expect_value(daemon::date_day_number("2026-12-10"), "a date");
  EXPECT_EQ(daemon::date_text(due), "2026-12-10");
  EXPECT_EQ(daemon::date_text(0), "1970-01-01");
  EXPECT_EQ(daemon::date_text(19783), "2024-03-01");
  EXPECT_EQ(daemon::date_text(-1), "1969-12-31");
  // A Unix time's day in UTC: midnight starts the day, the millisecond before it is the day before.
  EXPECT_EQ(daemon::utc_day(0), 0);
  EXPECT_EQ(daemon::utc_day(86'399'999), 0);
  EXPECT_EQ(daemon::utc_day(86'400'000), 1);
  EXPECT_EQ(daemon::utc_day(-1), -1);
  EXPECT_EQ(daemon::utc_day(due * 86'400'000 + 86'399'999), due);

  daemon::ReferenceEquipment e;
  e.table = daemon::ReferenceInstrument{"Acme Motion", "ATS-3", "T-0815", "2026-12-10", "DKD-123", "1 arcsec (k=2)"};
  const auto on = [&](std::int64_t day) {
    const auto judged = daemon::equipment_due(e, day);
    EXPECT_EQ(judged.size(), 1u);
    return judged.empty() ? daemon::InstrumentDue{} : judged.front();
  };
  // Eight days ahead: nothing to say; seven: due soon; the due day itself: still usable, due soon;
  // the day after: overdue.
  EXPECT_FALSE(on(due - 8).due_soon);
  EXPECT_FALSE(on(due - 8).overdue);
  EXPECT_EQ(on(due - 8).due_in_days, 8);
  EXPECT_TRUE(on(due - 7).due_soon);
  EXPECT_TRUE(on(due).due_soon);
  EXPECT_FALSE(on(due).overdue);
  EXPECT_EQ(on(due).due_in_days, 0);
  EXPECT_TRUE(on(due + 1).overdue);
  EXPECT_FALSE(on(due + 1).due_soon);
  EXPECT_EQ(on(due + 1).due_in_days, -1);
  EXPECT_EQ(on(due + 1).serial, "T-0815");
  EXPECT_EQ(daemon::overdue_text(daemon::equipment_due(e, due)), "");
  EXPECT_EQ(daemon::overdue_text(daemon::equipment_due(e, due + 1)),
            "the rate table (Acme Motion ATS-3, serial T-0815) was due for calibration on 2026-12-10");
  // The live page's lines and banner, written here only (web/js/equipment.mjs shows them).
  const std::string table = "The rate table (Acme Motion ATS-3, serial T-0815) ";
  EXPECT_EQ(daemon::due_line(on(due - 8)), table + "is due for calibration on 2026-12-10 (in 8 days).");
  EXPECT_EQ(daemon::due_line(on(due - 1)), table + "is due for calibration on 2026-12-10 (tomorrow).");
  EXPECT_EQ(daemon::due_line(on(due)), table + "is due for calibration on 2026-12-10 (today).");
  EXPECT_EQ(daemon::due_line(on(due + 1)), table + "was due for calibration on 2026-12-10 (1 day ago).");
  EXPECT_EQ(daemon::due_line(on(due + 30)), table + "was due for calibration on 2026-12-10 (30 days ago).");
  EXPECT_EQ(daemon::due_banner(daemon::equipment_due(e, due - 8)), "");
  EXPECT_NE(daemon::due_banner(daemon::equipment_due(e, due - 7)).find("no campaign starts without an operator's override"),
            std::string::npos);
  EXPECT_NE(daemon::due_banner(daemon::equipment_due(e, due + 1)).find("only when an operator overrides this with a reason"),
            std::string::npos);

  // All three instruments, in order; the JSON the certificate and the status carry is the rule's.
  daemon::DaemonConfig c;
  c.reference_equipment = e;
  c.reference_equipment.chamber = daemon::ReferenceInstrument{"ClimaCo", "CC-200", "C-4711", "2026-12-03", "", ""};
  c.reference_equipment.gravity = daemon::GravitySurvey{"Federal Geodesy Agency", "GS-2024-17", "2026-11-30"};
  c.site.gravity_mps2 = 9.81912;
  const auto all = daemon::equipment_due(c.reference_equipment, due - 7);
  ASSERT_EQ(all.size(), 3u);
  EXPECT_EQ(all[0].instrument, "table");
  EXPECT_EQ(all[1].instrument, "chamber");
  EXPECT_EQ(all[2].instrument, "gravity");
  EXPECT_TRUE(all[2].overdue);
  EXPECT_EQ(all[2].identity, "by Federal Geodesy Agency, certificate GS-2024-17");
  const json status = daemon::reference_equipment_json(c, due - 7, true);
  EXPECT_TRUE(status.at("table").at("due_soon").get<bool>());
  EXPECT_EQ(status.at("table").at("due_in_days"), 7);
  EXPECT_EQ(status.at("chamber").at("due_in_days"), 0);
  EXPECT_TRUE(status.at("gravity").at("overdue").get<bool>());
  EXPECT_EQ(status.at("gravity").at("text"),
            "The gravity survey (by Federal Geodesy Agency, certificate GS-2024-17) was due for a new survey on 2026-11-30 (3 days ago).");
  EXPECT_EQ(status.at("table").at("text"), daemon::due_line(all[0]));
  EXPECT_EQ(status.at("banner"), daemon::due_banner(all));
  EXPECT_DOUBLE_EQ(status.at("gravity").at("sigma_mps2").get<double>(), earth::site_gravity_sigma_mps2(c.site));
  const json certificate = daemon::reference_equipment_json(c, due - 7, false);
  EXPECT_FALSE(certificate.at("table").contains("due_in_days"));
  EXPECT_FALSE(certificate.at("table").contains("text")) << "a certificate states no day-relative words";
  EXPECT_FALSE(certificate.contains("banner"));
  EXPECT_EQ(certificate.at("table").at("overdue"), status.at("table").at("overdue"));
  c.reference_equipment = {};
  EXPECT_EQ(daemon::reference_equipment_json(c, due, true),
            json({{"table", nullptr}, {"chamber", nullptr}, {"gravity", nullptr}, {"banner", nullptr}}));
}

namespace {

std::string start_target(std::int64_t id) { return "/api/campaigns/" + std::to_string(id) + "/start"; }

// Today's date (UTC) `days` from now, as the configuration writes it.
std::string days_from_today(std::int64_t days) {
  return daemon::date_text(daemon::utc_day(daemon::now_unix_ms()) + days);
}

}  // namespace

// Issue 35, deliverable 4, its acceptance: a campaign with an expired table certificate refuses to
// start; an operator starts it anyway with a reason, which the audit trail keeps with their name.
TEST(ReferenceEquipment, AnExpiredTableRefusesTheStartUntilAnOperatorOverridesWithAReason) {
  LocalDaemon d("equipment-expired", false, [&](daemon::DaemonConfig& c) { configure_certified_bench(c, scratch_dir("equipment-site") + "/seq.json"); });
  const auto id = d.post_campaign(certificate_campaign("with an expired table", "FOG-41"));

  const auto refused = d.call("POST", start_target(id));
  ASSERT_EQ(refused.status, 409) << refused.body;
  const json why = json::parse(refused.body);
  const std::string error = why.at("error");
  for (const char* words : {"not started", "rate table", "T-0815", "2020-01-31", "override_overdue"})
    EXPECT_NE(error.find(words), std::string::npos) << words << " missing from: " << error;
  EXPECT_EQ(error.find("C-4711"), std::string::npos) << "the chamber is not overdue: " << error;
  ASSERT_EQ(why.at("overdue").size(), 1u);
  EXPECT_EQ(why.at("overdue")[0].at("instrument"), "table");
  EXPECT_EQ(why.at("overdue")[0].at("serial"), "T-0815");
  EXPECT_EQ(why.at("overdue")[0].at("calibration_due"), "2020-01-31");
  EXPECT_TRUE(why.at("overdue")[0].at("text").get<std::string>().starts_with(
      "The rate table (Acme Motion ATS-3, serial T-0815) was due for calibration on 2020-01-31 ("))
      << why.dump();
  EXPECT_EQ(d.campaign(id).at("state"), "created");

  // An override needs a reason; it belongs to start alone; a viewer cannot give one.
  const auto blank = d.call("POST", start_target(id), json{{"override_overdue", "  "}}.dump());
  EXPECT_EQ(blank.status, 400) << blank.body;
  EXPECT_NE(blank.body.find("body.override_overdue must say why"), std::string::npos) << blank.body;
  EXPECT_EQ(d.call("POST", start_target(id), json{{"override_overdue", 1}}.dump()).status, 400);
  const auto on_pause = d.call("POST", "/api/campaigns/" + std::to_string(id) + "/pause",
                               json{{"override_overdue", "why not"}}.dump());
  EXPECT_EQ(on_pause.status, 400) << on_pause.body;
  const auto viewer = d.call("POST", start_target(id), json{{"override_overdue", "I am only a viewer"}}.dump(), kViewerToken);
  EXPECT_EQ(viewer.status, 403) << viewer.body;
  EXPECT_EQ(d.campaign(id).at("state"), "created");
  EXPECT_TRUE(d.get("/api/audit?action=campaign.override_overdue").at("entries").empty());

  // The status the live page reads says so, judged today.
  const json status = d.get("/api/status");
  EXPECT_TRUE(status.at("reference_equipment").at("table").at("overdue").get<bool>());
  EXPECT_LT(status.at("reference_equipment").at("table").at("due_in_days").get<std::int64_t>(), 0);
  EXPECT_FALSE(status.at("reference_equipment").at("chamber").at("overdue").get<bool>());
  EXPECT_FALSE(status.at("reference_equipment").at("chamber").at("due_soon").get<bool>());
  EXPECT_NE(status.at("reference_equipment").at("banner").get<std::string>().find("only when an operator overrides"),
            std::string::npos) << status.at("reference_equipment").dump();

  const std::string reason = "customer deadline; table checked against the reference cube on 2026-11-20";
  const auto started = d.call("POST", start_target(id), json{{"override_overdue", reason}, {"reason", "yearly"}}.dump());
  ASSERT_EQ(started.status, 200) << started.body;
  EXPECT_EQ(json::parse(started.body).at("state"), "queued");
  const json trail = d.get("/api/audit?action=campaign.override_overdue");
  ASSERT_EQ(trail.at("entries").size(), 1u) << trail.dump();
  const json entry = trail.at("entries")[0];
  EXPECT_EQ(entry.at("actor"), "operator");
  EXPECT_EQ(entry.at("subject"), "campaign " + std::to_string(id));
  EXPECT_EQ(entry.at("details").at("reason"), reason);
  ASSERT_EQ(entry.at("details").at("instruments").size(), 1u);
  EXPECT_EQ(entry.at("details").at("instruments")[0].at("instrument"), "table");
  EXPECT_EQ(entry.at("details").at("instruments")[0].at("serial"), "T-0815");
  EXPECT_EQ(entry.at("details").at("instruments")[0].at("calibration_due"), "2020-01-31");
  EXPECT_TRUE(trail.at("intact").get<bool>());
  // The run's own record says it too: the start's transition names the override and its reason.
  const json run = d.campaign(id);
  const auto queued = std::find_if(run.at("transitions").begin(), run.at("transitions").end(),
                                   [](const json& t) { return t.at("to") == "queued"; });
  ASSERT_NE(queued, run.at("transitions").end()) << run.at("transitions").dump();
  const std::string transition = queued->at("reason");
  EXPECT_NE(transition.find("start by operator: yearly; overdue reference equipment overridden"), std::string::npos) << transition;
  EXPECT_NE(transition.find(reason), std::string::npos) << transition;
  EXPECT_EQ(d.command(id, "abort"), 200);
  d.wait_final(id);
  // Started already: a second start is the sequencer's 409, not judged again.
  const auto again = d.call("POST", start_target(id));
  EXPECT_EQ(again.status, 409);
  EXPECT_NE(again.body.find("already started"), std::string::npos) << again.body;
}

// Issue 35, deliverable 4: a run started under an operator's override of overdue equipment says so
// on its certificate, in the content that is hashed and signed: which instrument was past its due
// date (imucald's own words and each instrument's serial and date), the operator and the reason.
TEST(ReferenceEquipment, TheCertificateOfARunStartedUnderAnOverrideStatesWhoOverrodeWhichInstrumentAndWhy) {
  const std::string dir = scratch_dir("equipment-override-lab");
  const std::string key_file = dir + "/lab.key";
  signing::write_key_file(key_file, signing::generate_key_pair());
  const signing::PublicKey lab_key = signing::read_public_key(key_file + ".pub");
  LocalDaemon d("equipment-override", false, [&](daemon::DaemonConfig& c) {
    configure_certified_bench(c, dir + "/sequence.json");
    c.certificates.signing_key_file = key_file;
  });
  const auto id = d.post_campaign(certificate_campaign("started under an override", "FOG-51"));
  const std::string reason = "customer deadline; table checked against the reference cube on 2026-11-20";
  const auto started = d.call("POST", start_target(id), json{{"override_overdue", reason}}.dump());
  ASSERT_EQ(started.status, 200) << started.body;

  // Kept with the run from its start (GET /api/campaigns/{id}).
  const json kept = d.campaign(id).at("override_overdue");
  ASSERT_TRUE(kept.is_object()) << kept.dump();
  EXPECT_EQ(kept.at("by"), "operator");
  EXPECT_EQ(kept.at("reason"), reason);
  EXPECT_EQ(kept.at("text"), "the rate table (Acme Motion ATS-3, serial T-0815) was due for calibration on 2020-01-31");
  ASSERT_EQ(kept.at("instruments").size(), 1u) << kept.dump();
  EXPECT_EQ(kept.at("instruments")[0].at("instrument"), "table");
  EXPECT_EQ(kept.at("instruments")[0].at("serial"), "T-0815");
  EXPECT_EQ(kept.at("instruments")[0].at("calibration_due"), "2020-01-31");
  EXPECT_FALSE(kept.at("instruments")[0].contains("text")) << "no words counting days from a day gone by";
  EXPECT_TRUE(std::regex_match(kept.at("at").get<std::string>(), std::regex(R"(\d{4}-\d\d-\d\dT.*Z)"))) << kept.dump();

  ASSERT_EQ(d.wait_final(id).at("state"), "done");
  const json cert = d.get(certificate_target(id));
  ASSERT_TRUE(cert.contains("content")) << cert.dump().substr(0, 600);
  EXPECT_EQ(cert.at("content").at("campaign").at("override_overdue"), kept) << cert.at("content").at("campaign").dump();
  // The certificate's table line says OVERDUE as well (judged on the day the run ended).
  EXPECT_TRUE(cert.at("content").at("bench").at("reference_equipment").at("table").at("overdue").get<bool>());
  // In what is hashed and signed: the envelope carries it and verifies with the lab's key.
  EXPECT_EQ(signing::sha256_hex(signing::canonical_json(cert.at("content"))), cert.at("content_sha256").get<std::string>());
  EXPECT_EQ(cert.at("signed").at("content").at("campaign").at("override_overdue"), kept);
  const signing::Verification v = signing::verify_document(cert.at("signed"), lab_key);
  EXPECT_TRUE(v.verified()) << v.message;
}

// Due in three days: the start goes ahead (no override asked, none audited) and the status the
// live page reads says the table is due soon.
TEST(ReferenceEquipment, DueWithinAWeekStartsAndTheStatusSaysDueSoon) {
  LocalDaemon d("equipment-due-soon", false, [&](daemon::DaemonConfig& c) {
    configure_certified_bench(c, scratch_dir("equipment-soon-site") + "/seq.json");
    c.reference_equipment.table->calibration_due = days_from_today(3);
    c.reference_equipment.gravity->calibration_due = days_from_today(8);
  });
  const json status = d.get("/api/status");
  const json table = status.at("reference_equipment").at("table");
  EXPECT_TRUE(table.at("due_soon").get<bool>()) << table.dump();
  EXPECT_FALSE(table.at("overdue").get<bool>());
  // (2 if midnight UTC passed since the configuration was made.)
  EXPECT_GE(table.at("due_in_days").get<std::int64_t>(), 2);
  EXPECT_LE(table.at("due_in_days").get<std::int64_t>(), 3);
  EXPECT_EQ(table.at("uncertainty"), "1 arcsec (k=2)");
  EXPECT_FALSE(status.at("reference_equipment").at("chamber").at("due_soon").get<bool>());
  EXPECT_EQ(status.at("reference_equipment").at("gravity").at("surveyed_by"), "Federal Geodesy Agency");
  EXPECT_GE(status.at("reference_equipment").at("gravity").at("due_in_days").get<std::int64_t>(), 7);
  EXPECT_TRUE(table.at("text").get<std::string>().starts_with(
      "The rate table (Acme Motion ATS-3, serial T-0815) is due for calibration on " +
      table.at("calibration_due").get<std::string>() + " (in "))
      << table.dump();
  EXPECT_EQ(status.at("reference_equipment").at("banner"), "After its due date no campaign starts without an operator's override.");

  const auto id = d.post_campaign(certificate_campaign("table due soon", "FOG-42"));
  const auto started = d.call("POST", start_target(id));
  ASSERT_EQ(started.status, 200) << started.body;
  // An override where nothing is overdue changes nothing and is not audited as one.
  const auto other = d.post_campaign(certificate_campaign("needless override", "FOG-43"));
  ASSERT_EQ(d.call("POST", start_target(other), json{{"override_overdue", "just in case"}}.dump()).status, 200);
  EXPECT_TRUE(d.get("/api/audit?action=campaign.override_overdue").at("entries").empty());
  EXPECT_EQ(d.wait_final(id).at("state"), "done");
  EXPECT_EQ(d.wait_final(other).at("state"), "done");
  const json cert = d.get(certificate_target(id));
  EXPECT_FALSE(cert.at("reference_equipment").at("table").at("overdue").get<bool>()) << cert.dump().substr(0, 600);
  // Nothing was overridden: neither run records an override, nor does its certificate state one.
  for (const auto run : {id, other}) {
    EXPECT_TRUE(d.campaign(run).at("override_overdue").is_null()) << run;
    const json stated = d.get(certificate_target(run)).at("content").at("campaign");
    EXPECT_FALSE(stated.contains("override_overdue")) << stated.dump().substr(0, 600);
  }
}

namespace {

// `imucal campaign run` (the command line `run`) refused: the overdue table named with its due date
// and the flag that overrides it; an override without a reason refused too.
void expect_refused_unless_a_reason_is_given(const std::string& run) {
  const auto refused = run_imucal_cli(run);
  EXPECT_EQ(refused.first, 2) << refused.second;
  for (const char* words : {"not started", "rate table", "T-0815", "2020-01-31", "--override-overdue"})
    EXPECT_NE(refused.second.find(words), std::string::npos) << words << " missing from: " << refused.second;
  EXPECT_EQ(refused.second.find("C-4711"), std::string::npos) << "the chamber is not overdue: " << refused.second;
  const auto blank = run_imucal_cli(run + " --override-overdue ' '");
  EXPECT_EQ(blank.first, 2) << blank.second;
  EXPECT_NE(blank.second.find("--override-overdue must say why"), std::string::npos) << blank.second;
}

// The data directory after the two refusals and the overridden run of FOG-61: the refused
// campaigns created but never started and never overridden, the run's certificate stating who
// overrode what and why, and the audit trail's one entry of it.
void expect_override_recorded(const std::string& data_dir, const std::string& reason) {
  daemon::DaemonDb db(data_dir + "/imucald.db");
  const auto campaigns = db.unit_campaigns(std::string("FOG-61"));
  ASSERT_EQ(campaigns.size(), 3u);  // two refused (still created), one run
  const auto done = campaigns.back();
  EXPECT_EQ(done.state, daemon::RunState::Done);
  for (std::size_t i = 0; i + 1 < campaigns.size(); ++i) {
    EXPECT_EQ(campaigns[i].state, daemon::RunState::Created);
    EXPECT_FALSE(db.overdue_override(campaigns[i].id).has_value());
  }
  const auto certificate = db.current_issued(done.id);
  ASSERT_TRUE(certificate.has_value());
  const json stated = json::parse(certificate->content_json).at("campaign").at("override_overdue");
  EXPECT_EQ(stated.at("by"), "alice");
  EXPECT_EQ(stated.at("reason"), reason);
  EXPECT_EQ(stated.at("text"), "the rate table (Acme Motion ATS-3, serial T-0815) was due for calibration on 2020-01-31");
  daemon::DaemonDb::AuditQuery query;
  query.action_prefix = "campaign.override_overdue";
  const auto trail = db.audit_entries(query);
  ASSERT_EQ(trail.size(), 1u);
  EXPECT_EQ(trail[0].actor, "alice");
  EXPECT_EQ(trail[0].subject, "campaign " + std::to_string(done.id));
}

}  // namespace

// `imucal campaign run` (no daemon) judges the configuration's reference equipment with imucald's
// own code: refused naming the instrument and its due date, unless given --override-overdue with a
// reason, which is then recorded with the run, audited and stated on its certificate.
TEST(ReferenceEquipment, CampaignRunRefusesOverdueEquipmentUnlessOverriddenWithAReason) {
  const std::string dir = scratch_dir("equipment-campaign-run");
  const std::string config = dir + "/imucald.json";
  const std::string campaign = dir + "/campaign.json";
  std::ofstream(config) << json{{"certificates", {{"prefix", "RUN"}, {"sequence_file", dir + "/sequence.json"}}},
                                {"reference_equipment",
                                 {{"table", {{"make", "Acme Motion"}, {"model", "ATS-3"}, {"serial", "T-0815"},
                                             {"calibration_due", "2020-01-31"}}},
                                  {"chamber", {{"make", "ClimaCo"}, {"model", "CC-200"}, {"serial", "C-4711"},
                                               {"calibration_due", "2999-12-31"}}}}}}
                               .dump(1);
  std::ofstream(campaign) << certificate_campaign("from the command line", "FOG-61").dump(1);
  const std::string run = "campaign run '" + campaign + "' --config '" + config + "' --data-dir '" + dir + "/data'";
  expect_refused_unless_a_reason_is_given(run);

  const std::string reason = "rehearsal of the overdue table on the simulated bench";
  const auto overridden = run_imucal_cli(run + " --override-overdue '" + reason + "' --operator alice");
  ASSERT_EQ(overridden.first, 0) << overridden.second;
  EXPECT_NE(overridden.second.find("overridden by alice: " + reason), std::string::npos) << overridden.second;
  expect_override_recorded(dir + "/data", reason);
}
