// Calibration certificates (issue 17, deliverable 5): numbers with the site's prefix that never
// repeat (not across campaigns, not across a new data directory, not between two daemons sharing
// the sequence file), the same number every time a campaign's certificate is asked for, no number
// for a run that has not ended, and the bench a certificate states (reference equipment, gravity),
// with the configuration's errors naming the field at fault.
#include <gtest/gtest.h>
#include <sys/wait.h>

#include <algorithm>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <map>
#include <mutex>
#include <regex>
#include <set>
#include <thread>

#include "core/earth.hpp"
#include "core/expect_value.hpp"
#include "daemon/production/reference_equipment.hpp"
#include "daemon/production/certificates.hpp"
#include "daemon/registry/certificate_sequence.hpp"
#include "daemon/registry/postgres_registry.hpp"
#include "service_fixture.hpp"
#include "signing/signing.hpp"
#include "storage/sqlite.hpp"
#include "tests/postgres_server.hpp"
#include "tests/test_paths.hpp"

using namespace imucal;
using namespace imucal::daemontest;
using imucal::daemon::CertificateSequence;
using imucal::daemon::ConfigError;
using imucal::daemon::parse_config;

namespace {

json certificate_campaign(const std::string& name, const std::string& serial) {
  return direct_short_calibration(name, {{"serial", serial}, {"part_number", "PN-100"}});
}

// Starts a campaign with an operator's override of the overdue table (configure() below names a
// table whose calibration ran out in 2020): its certificates then state the table as overdue.
int start_overriding(LocalDaemon& d, std::int64_t id) {
  const auto r = d.call("POST", "/api/campaigns/" + std::to_string(id) + "/start",
                        json{{"override_overdue", "test bench: the overdue table is what the certificate must state"}}.dump());
  EXPECT_EQ(r.status, 200) << r.body;
  return r.status;
}

// A campaign run to its end on the simulated bench.
std::int64_t run_campaign(LocalDaemon& d, const std::string& name, const std::string& serial) {
  const auto id = d.post_campaign(certificate_campaign(name, serial));
  start_overriding(d, id);
  EXPECT_EQ(d.wait_final(id).at("state"), "done");
  return id;
}

std::string certificate_target(std::int64_t id) { return "/api/campaigns/" + std::to_string(id) + "/certificate"; }

// The configuration's message for `text` (empty when it is accepted).
std::string config_error(const std::string& text) {
  try {
    parse_config(text, "test.json");
  } catch (const ConfigError& e) {
    return e.what();
  }
  return {};
}

void configure(daemon::DaemonConfig& c, const std::string& sequence_file) {
  c.certificates.prefix = "LAB";
  c.certificates.sequence_file = sequence_file;
  c.reference_equipment.table =
      daemon::ReferenceInstrument{"Acme Motion", "ATS-3", "T-0815", "2020-01-31", "DKD-123", "1 arcsec (k=2)"};
  c.reference_equipment.chamber = daemon::ReferenceInstrument{"ClimaCo", "CC-200", "C-4711", "2999-12-31", "", ""};
  c.reference_equipment.gravity = daemon::GravitySurvey{"Federal Geodesy Agency", "GS-2024-17", "2999-12-31"};
  c.site.gravity_mps2 = 9.81912;
}

// `imucal ARGS`: its exit status and what it printed (standard output and error).
std::pair<int, std::string> run_imucal(const std::string& args) {
  const std::string command = imucaltest::program("imucal") + " " + args + " 2>&1";
  std::string out;
  FILE* p = ::popen(command.c_str(), "r");
  if (!p) return {-1, "popen failed"};
  char buf[512];
  while (std::fgets(buf, sizeof buf, p)) out += buf;
  const int status = ::pclose(p);
  return {WIFEXITED(status) ? WEXITSTATUS(status) : -1, out};
}

}  // namespace

TEST(Certificate, NumbersNeverRepeatAcrossCampaignsAndDataDirectories) {
  const std::string sequence_file = scratch_dir("certificate-site") + "/sequence.json";
  std::string first_number, second_number;
  {
    LocalDaemon d("certificate-a", false, [&](daemon::DaemonConfig& c) { configure(c, sequence_file); });
    const auto a = run_campaign(d, "first", "FOG-7");
    const auto b = run_campaign(d, "second", "FOG-8");

    const auto ra = d.call("GET", certificate_target(a));
    ASSERT_EQ(ra.status, 200) << ra.body;
    const json ca = json::parse(ra.body);
    first_number = ca.at("number");
    EXPECT_TRUE(std::regex_match(first_number, std::regex("LAB-\\d{4}-\\d{6}"))) << first_number;
    EXPECT_EQ(ca.at("campaign_id"), a);

    // Asked again (by a viewer too): the same number, the same date of issue.
    const auto again = d.call("GET", certificate_target(a), "", kViewerToken);
    ASSERT_EQ(again.status, 200) << again.body;
    EXPECT_EQ(json::parse(again.body).at("number"), first_number);
    EXPECT_EQ(json::parse(again.body).at("issued"), ca.at("issued"));

    const json cb = d.get(certificate_target(b));
    second_number = cb.at("number");
    EXPECT_NE(second_number, first_number);
    EXPECT_EQ(cb.at("sequence").get<std::int64_t>(), ca.at("sequence").get<std::int64_t>() + 1);

    // What the certificate states about the bench: the equipment with its due date judged against
    // the day of the run, the simulated devices, the configured gravity.
    EXPECT_TRUE(ca.at("simulated").get<bool>());
    EXPECT_EQ(ca.at("reference_equipment").at("table").at("serial"), "T-0815");
    EXPECT_EQ(ca.at("reference_equipment").at("table").at("calibration_certificate"), "DKD-123");
    EXPECT_TRUE(ca.at("reference_equipment").at("table").at("overdue").get<bool>());
    EXPECT_FALSE(ca.at("reference_equipment").at("chamber").at("overdue").get<bool>());
    EXPECT_TRUE(ca.at("reference_equipment").at("chamber").at("calibration_certificate").is_null());
    EXPECT_EQ(ca.at("reference_equipment").at("table").at("uncertainty"), "1 arcsec (k=2)");
    EXPECT_TRUE(ca.at("reference_equipment").at("chamber").at("uncertainty").is_null());
    // The gravity survey: its certificate, its due date, and the 1-sigma the calibration used for g.
    const json survey = ca.at("reference_equipment").at("gravity");
    EXPECT_EQ(survey.at("surveyed_by"), "Federal Geodesy Agency");
    EXPECT_EQ(survey.at("calibration_certificate"), "GS-2024-17");
    EXPECT_EQ(survey.at("calibration_due"), "2999-12-31");
    EXPECT_FALSE(survey.at("overdue").get<bool>());
    EXPECT_DOUBLE_EQ(survey.at("sigma_mps2").get<double>(), earth::kMeasuredGravitySigma_mps2);
    EXPECT_DOUBLE_EQ(ca.at("gravity").at("sigma_mps2").get<double>(), earth::kMeasuredGravitySigma_mps2);
    // A certificate judges the day the run ended, not today: no "due soon" on it.
    EXPECT_FALSE(ca.at("reference_equipment").at("table").contains("due_soon"));
    EXPECT_EQ(ca.at("gravity").at("source"), "configured");
    EXPECT_DOUBLE_EQ(ca.at("gravity").at("value_mps2").get<double>(), 9.81912);

    // No number for a run that has not ended, nor for a campaign that does not exist.
    const auto pending = d.post_campaign(certificate_campaign("not run", "FOG-9"));
    const auto refused = d.call("GET", certificate_target(pending));
    EXPECT_EQ(refused.status, 409);
    EXPECT_NE(json::parse(refused.body).at("error").get<std::string>().find("has not ended (state created)"),
              std::string::npos)
        << refused.body;
    EXPECT_EQ(d.call("GET", certificate_target(9999)).status, 404);
    EXPECT_EQ(d.call("POST", certificate_target(a)).status, 405);
  }
  // A new data directory, the same site's sequence file: the count goes on.
  LocalDaemon fresh("certificate-b", false, [&](daemon::DaemonConfig& c) {
    configure(c, sequence_file);
    c.site.gravity_mps2.reset();
    c.reference_equipment.gravity.reset();  // nothing measured: no survey
  });
  const auto c = run_campaign(fresh, "after a new data directory", "FOG-7");
  const json cc = fresh.get(certificate_target(c));
  const std::string third_number = cc.at("number");
  EXPECT_NE(third_number, first_number);
  EXPECT_NE(third_number, second_number);
  EXPECT_EQ(third_number.substr(third_number.size() - 6), "000003") << third_number;
  EXPECT_EQ(cc.at("gravity").at("source"), "normal_gravity");
  EXPECT_DOUBLE_EQ(cc.at("gravity").at("sigma_mps2").get<double>(), earth::kNormalGravitySigma_mps2);
  EXPECT_TRUE(cc.at("reference_equipment").at("gravity").is_null());
  EXPECT_DOUBLE_EQ(cc.at("gravity").at("value_mps2").get<double>(), earth::site_gravity_mps2(fresh.config.site));
}

namespace {

// Two daemons on one site take 40 numbers each at once, each through its own descriptor of the
// lock file, the second's clock `offset_ms` off the first's: each number taken, with the time of
// issue it states.
std::map<std::int64_t, std::int64_t> take_at_once(CertificateSequence& one, CertificateSequence& two,
                                                  std::int64_t offset_ms) {
  std::map<std::int64_t, std::int64_t> issued_ms;
  std::mutex mutex;
  const auto take = [&](CertificateSequence& sequence, std::int64_t clock_offset_ms) {
    for (int i = 0; i < 40; ++i) {
      const CertificateSequence::Taken t = sequence.take(0, daemon::now_unix_ms() + clock_offset_ms);
      std::lock_guard lock(mutex);
      issued_ms[t.number] = t.issued_ms;
    }
  };
  std::thread t1([&] { take(one, 0); });
  std::thread t2([&] { take(two, offset_ms); });
  t1.join();
  t2.join();
  return issued_ms;
}

}  // namespace

TEST(Certificate, SequenceFileIsSharedSafelyAndNeverGoesBack) {
  const std::string dir = scratch_dir("certificate-sequence");
  const std::string path = dir + "/sequence.json";
  CertificateSequence one(path), two(path);
  // The second daemon's clock an hour behind the first's: 80 numbers, none taken twice, each
  // stating an issue no earlier than the number before it, whichever daemon took it.
  const std::map<std::int64_t, std::int64_t> issued_ms = take_at_once(one, two, -3'600'000);
  ASSERT_EQ(issued_ms.size(), 80u) << "a number taken twice";
  EXPECT_EQ(issued_ms.rbegin()->first, 80);
  EXPECT_EQ(one.last(), 80);
  std::int64_t before_ms = 0;
  for (const auto& number_time : issued_ms) {
    EXPECT_LE(before_ms, number_time.second) << "number " << number_time.first << " states an earlier issue than the one before";
    before_ms = number_time.second;
  }

  // A sequence file behind the database (restored from an old backup) does not go back.
  EXPECT_EQ(one.take(500, 0).number, 501);
  EXPECT_EQ(one.take(0, 0).number, 502);
  // A file written before the times were kept: numbered on, the time this daemon's clock.
  std::ofstream(path) << R"({"format": "imucal-certificate-sequence/1", "last": 7})";
  const CertificateSequence::Taken after_old = one.take(0, 1234);
  EXPECT_EQ(after_old.number, 8);
  EXPECT_EQ(after_old.issued_ms, 1234);

  // A damaged file stops the numbering and says which file.
  std::ofstream(path) << "{\"last\": ";
  try {
    one.take(0, 0);
    ADD_FAILURE() << "a damaged sequence file was accepted";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find(path), std::string::npos) << e.what();
  }
  EXPECT_EQ(daemon::certificate_number("LAB", 2026, 123), "LAB-2026-000123");
  EXPECT_EQ(daemon::certificate_number("LAB", 2026, 1234567), "LAB-2026-1234567");
}

TEST(Certificate, ConfigurationNamesTheFieldAtFault) {
  const std::string good_table =
      R"("table": {"make": "Acme", "model": "ATS-3", "serial": "T-1", "calibration_due": "2027-02-28"})";
  const daemon::DaemonConfig ok = parse_config(R"({"reference_equipment": {)" + good_table +
                                                   R"(}, "certificates": {"prefix": "LAB-1"}})", "ok.json");
  ASSERT_TRUE(ok.reference_equipment.table.has_value());
  EXPECT_EQ(ok.reference_equipment.table->calibration_due, "2027-02-28");
  EXPECT_FALSE(ok.reference_equipment.chamber.has_value());
  EXPECT_EQ(daemon::certificate_prefix(ok), "LAB-1");

  const std::string missing = config_error(
      R"({"reference_equipment": {"chamber": {"make": "ClimaCo", "model": "CC", "calibration_due": "2027-01-01"}}})");
  EXPECT_NE(missing.find("config.reference_equipment.chamber.serial is required"), std::string::npos) << missing;
  const std::string bad_date = config_error(
      R"({"reference_equipment": {"table": {"make": "A", "model": "B", "serial": "C", "calibration_due": "2027-02-30"}}})");
  EXPECT_NE(bad_date.find("config.reference_equipment.table.calibration_due must be a date YYYY-MM-DD, not \"2027-02-30\""),
            std::string::npos)
      << bad_date;
  const std::string empty = config_error(
      R"({"reference_equipment": {"table": {"make": " ", "model": "B", "serial": "C", "calibration_due": "2027-01-01"}}})");
  EXPECT_NE(empty.find("config.reference_equipment.table.make must not be empty"), std::string::npos) << empty;
  const std::string typo = config_error(R"({"reference_equipment": {"tabel": {}}})");
  EXPECT_NE(typo.find("tabel"), std::string::npos) << typo;
  // Uncertainties as the instruments' certificates state them; the gravity survey of the measured g.
  const daemon::DaemonConfig full = parse_config(R"j({"site": {"gravity_mps2": 9.81912}, "reference_equipment": {
      "table": {"make": "A", "model": "B", "serial": "C", "calibration_due": "2027-01-01", "uncertainty": "1 arcsec (k=2)"},
      "gravity": {"surveyed_by": "Federal Geodesy Agency", "calibration_certificate": "GS-1", "calibration_due": "2030-06-30"}}})j",
                                                 "full.json");
  ASSERT_TRUE(full.reference_equipment.table.has_value());
  EXPECT_EQ(full.reference_equipment.table->uncertainty, "1 arcsec (k=2)");
  ASSERT_TRUE(full.reference_equipment.gravity.has_value());
  EXPECT_EQ(full.reference_equipment.gravity->calibration_certificate, "GS-1");
  EXPECT_EQ(full.reference_equipment.gravity->calibration_due, "2030-06-30");
  const std::string blank_uncertainty = config_error(
      R"({"reference_equipment": {"table": {"make": "A", "model": "B", "serial": "C", "calibration_due": "2027-01-01", "uncertainty": ""}}})");
  EXPECT_NE(blank_uncertainty.find("config.reference_equipment.table.uncertainty must say"), std::string::npos) << blank_uncertainty;
  const std::string survey_date = config_error(
      R"({"site": {"gravity_mps2": 9.81}, "reference_equipment": {"gravity": {"surveyed_by": "X", "calibration_certificate": "G", "calibration_due": "30.06.2030"}}})");
  EXPECT_NE(survey_date.find("config.reference_equipment.gravity.calibration_due must be a date YYYY-MM-DD, not \"30.06.2030\""),
            std::string::npos)
      << survey_date;
  const std::string survey_missing =
      config_error(R"({"site": {"gravity_mps2": 9.81}, "reference_equipment": {"gravity": {"surveyed_by": "X", "calibration_due": "2030-01-01"}}})");
  EXPECT_NE(survey_missing.find("config.reference_equipment.gravity.calibration_certificate is required"), std::string::npos)
      << survey_missing;
  // The survey's uncertainty is the one number the calibration uses, never a second one here.
  const std::string survey_sigma = config_error(R"({"site": {"gravity_mps2": 9.81}, "reference_equipment": {"gravity":
      {"surveyed_by": "X", "calibration_certificate": "G", "calibration_due": "2030-01-01", "uncertainty": "0.02 mGal"}}})");
  EXPECT_NE(survey_sigma.find("config.reference_equipment.gravity.uncertainty is not configured"), std::string::npos) << survey_sigma;
  const std::string no_g = config_error(
      R"({"reference_equipment": {"gravity": {"surveyed_by": "X", "calibration_certificate": "G", "calibration_due": "2030-01-01"}}})");
  EXPECT_NE(no_g.find("config.site.gravity_mps2 (the g it measured) is not set"), std::string::npos) << no_g;
  const std::string prefix = config_error(R"({"certificates": {"prefix": "LAB 1"}})");
  EXPECT_NE(prefix.find("config.certificates.prefix must be"), std::string::npos) << prefix;

  // Defaults: the prefix from the site's name, the sequence file beside the configuration file.
  daemon::DaemonConfig d = parse_config(R"({"site": {"name": "Lab 2 / hall B"}})", "x");
  EXPECT_EQ(daemon::certificate_prefix(d), "LAB-2-HALL-B");
  d.site_name = "";
  EXPECT_EQ(daemon::certificate_prefix(d), "IMUCAL");
  const std::string dir = scratch_dir("certificate-config");
  std::ofstream(dir + "/imucald.json") << R"({"certificates": {"sequence_file": "seq/numbers.json"}})";
  EXPECT_EQ(daemon::certificate_sequence_path(daemon::load_config_file(dir + "/imucald.json")),
            (std::filesystem::absolute(dir) / "seq/numbers.json").string());
  std::ofstream(dir + "/plain.json") << "{}";
  EXPECT_EQ(daemon::certificate_sequence_path(daemon::load_config_file(dir + "/plain.json")),
            (std::filesystem::absolute(dir) / "imucal-certificate-sequence.json").string());
}

TEST(Certificate, DatesAreDaysOfTheGregorianCalendar) {
  EXPECT_EQ(daemon::date_day_number("1970-01-01"), 0);
  EXPECT_EQ(daemon::date_day_number("2000-03-01"), 11017);
  EXPECT_EQ(daemon::date_day_number("2024-02-28"), 19781);
  EXPECT_EQ(daemon::date_day_number("2024-03-01"), 19783);  // two days later: a leap year
  EXPECT_FALSE(daemon::date_day_number("2023-02-29"));
  EXPECT_FALSE(daemon::date_day_number("2026-13-01"));
  EXPECT_FALSE(daemon::date_day_number("2026-1-01"));
  EXPECT_FALSE(daemon::date_day_number("tomorrow"));
}

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
  LocalDaemon d("equipment-expired", false, [&](daemon::DaemonConfig& c) { configure(c, scratch_dir("equipment-site") + "/seq.json"); });
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
    configure(c, dir + "/sequence.json");
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
    configure(c, scratch_dir("equipment-soon-site") + "/seq.json");
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

// Issue 35, deliverable 1, in part: a certificate issued with one site g, read after the
// configuration's g was corrected, says so (its content unchanged), and the unit's page lists it.
// (Superseding it: the next test.)
TEST(Certificate, ACorrectedSiteGravityIsReportedOnTheCertificatesIssuedWithTheOldOne) {
  const std::string dir = scratch_dir("gravity-corrected-lab");
  LocalDaemon d("gravity-corrected", false, [&](daemon::DaemonConfig& c) { configure(c, dir + "/sequence.json"); });
  const auto id = run_campaign(d, "before the correction", "FOG-71");
  const json before = d.get(certificate_target(id));
  ASSERT_TRUE(before.contains("number")) << before.dump().substr(0, 400);
  EXPECT_TRUE(before.at("gravity_corrected").is_null()) << before.at("gravity_corrected");
  EXPECT_TRUE(d.get("/api/imus/FOG-71").at("gravity_corrected").empty());

  // The site surveyed again: imucald restarted on the same data directory with the corrected g.
  d.service->stop();
  d.service.reset();
  d.config.site.gravity_mps2 = 9.81925;
  d.service = std::make_unique<daemon::Service>(d.config);
  d.service->start(false);
  const json after = d.get(certificate_target(id));
  EXPECT_EQ(after.at("number"), before.at("number")) << "not reissued";
  EXPECT_EQ(after.at("content"), before.at("content")) << "the issued content never changes";
  const json corrected = after.at("gravity_corrected");
  ASSERT_TRUE(corrected.is_object()) << after.dump().substr(0, 400);
  EXPECT_DOUBLE_EQ(corrected.at("issued_with_mps2").get<double>(), 9.81912);
  EXPECT_DOUBLE_EQ(corrected.at("now_mps2").get<double>(), 9.81925);
  EXPECT_EQ(corrected.at("source_now"), "configured");
  const std::string text = corrected.at("text");
  for (const char* words : {"corrected since this certificate was issued", "9.81912", "9.81925"})
    EXPECT_NE(text.find(words), std::string::npos) << words << " missing from: " << text;
  const json unit = d.get("/api/imus/FOG-71");
  ASSERT_EQ(unit.at("gravity_corrected").size(), 1u) << unit.at("gravity_corrected");
  EXPECT_EQ(unit.at("gravity_corrected")[0].at("number"), before.at("number"));
  EXPECT_EQ(unit.at("gravity_corrected")[0].at("campaign_id"), id);

  // A run after the correction is certified with the corrected g: nothing to say of it.
  const auto later = run_campaign(d, "after the correction", "FOG-71");
  EXPECT_TRUE(d.get(certificate_target(later)).at("gravity_corrected").is_null());
  EXPECT_EQ(d.get("/api/imus/FOG-71").at("gravity_corrected").size(), 1u);
}

// Issue 35, deliverable 1: a corrected site g supersedes the certificates issued with the old one.
// An operator has the run calibrated again from its recording with the corrected g (a job, polled
// as the analyses are); the new certificate states the new g and the model it gives, numbered next
// and superseding the old, which stays as issued. The accelerometers' scale factors move by the
// relative change of g (a reference 100 ppm larger reads as a unit 100 ppm less sensitive); the
// gyros, calibrated against the Earth's rate, do not move.
TEST(Certificate, ACorrectedSiteGravitySupersedesTheCertificateWithTheRunCalibratedAgain) {
  const std::string dir = scratch_dir("gravity-recalibrated-lab");
  LocalDaemon d("gravity-recalibrated", false, [&](daemon::DaemonConfig& c) { configure(c, dir + "/sequence.json"); });
  const auto id = run_campaign(d, "before the survey", "FOG-72");
  const std::string target = "/api/campaigns/" + std::to_string(id) + "/recalibrate";
  const json old_cert = d.get(certificate_target(id));
  ASSERT_TRUE(old_cert.contains("number")) << old_cert.dump().substr(0, 400);
  const auto nothing = d.call("POST", target, json{{"reason", "no survey yet"}}.dump());
  EXPECT_EQ(nothing.status, 409) << nothing.body;
  EXPECT_NE(nothing.body.find("nothing to calibrate again"), std::string::npos) << nothing.body;

  d.service->stop();
  d.service.reset();
  const double g_old = 9.81912, g_new = 9.82012;
  d.config.site.gravity_mps2 = g_new;
  d.service = std::make_unique<daemon::Service>(d.config);
  d.service->start(false);
  const auto no_reason = d.call("POST", target, json{{"reason", " "}}.dump());
  EXPECT_EQ(no_reason.status, 400) << no_reason.body;
  EXPECT_NE(no_reason.body.find("body.reason must say why the run is calibrated again"), std::string::npos) << no_reason.body;

  const std::string reason = "survey GS-2026-03 replaced GS-2024-17";
  auto r = d.call("POST", target, json{{"reason", reason}}.dump());
  for (const auto deadline = std::chrono::steady_clock::now() + std::chrono::minutes(5);
       r.status == 202 && std::chrono::steady_clock::now() < deadline;) {
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
    r = d.call("POST", target, json{{"reason", reason}}.dump());
  }
  ASSERT_EQ(r.status, 200) << r.body;
  const json answer = json::parse(r.body);
  const json cert = answer.at("certificate");
  EXPECT_EQ(answer.at("superseded"), old_cert.at("number"));
  EXPECT_EQ(cert.at("supersedes"), old_cert.at("number"));
  EXPECT_EQ(cert.at("sequence").get<int>(), old_cert.at("sequence").get<int>() + 1) << "numbered next";
  EXPECT_NE(cert.at("reason").get<std::string>().find(reason), std::string::npos) << cert.at("reason");
  EXPECT_DOUBLE_EQ(cert.at("content").at("bench").at("gravity").at("value_mps2").get<double>(), g_new);

  // The old one as issued, marked superseded; the campaign's certificate in force is the new one.
  const json old_now = d.get("/api/certificates/" + old_cert.at("number").get<std::string>());
  EXPECT_EQ(old_now.at("content"), old_cert.at("content")) << "an issued certificate never changes";
  EXPECT_EQ(old_now.at("content_sha256"), old_cert.at("content_sha256"));
  EXPECT_EQ(old_now.at("superseded_by"), cert.at("number"));
  const json in_force = d.get(certificate_target(id));
  EXPECT_EQ(in_force.at("number"), cert.at("number"));
  EXPECT_TRUE(in_force.at("gravity_corrected").is_null()) << in_force.at("gravity_corrected");
  EXPECT_TRUE(d.get("/api/imus/FOG-72").at("gravity_corrected").empty());

  // The model moved as the corrected g says, and only the accelerometers' scale factors did.
  const json& before = old_cert.at("content").at("model");
  const json& after = cert.at("content").at("model");
  const double expected_ppm = -(g_new - g_old) / g_new * 1e6;  // about -101.8 ppm
  for (int axis = 0; axis < 3; ++axis) {
    const double moved_ppm = after.at("accel").at("scale_ppm")[axis].get<double>() - before.at("accel").at("scale_ppm")[axis].get<double>();
    EXPECT_NEAR(moved_ppm, expected_ppm, 0.05) << "accelerometer " << axis;  // measured: within 0.005
    for (const char* key : {"scale_pos_ppm", "bias_dph"})
      EXPECT_NEAR(after.at("gyro").at(key)[axis].get<double>(), before.at("gyro").at(key)[axis].get<double>(), 1e-6)
          << "gyro " << key << " " << axis;
  }
  EXPECT_EQ(d.get("/api/campaigns/" + std::to_string(id) + "/model"), after) << "the campaign's model is the recalibrated one";

  // Asked again: the answer kept, no third certificate; the audit trail has who, why and both g.
  const auto again = d.call("POST", target, json{{"reason", reason}}.dump());
  ASSERT_EQ(again.status, 200) << again.body;
  EXPECT_EQ(json::parse(again.body).at("certificate").at("number"), cert.at("number"));
  const json audit = d.get("/api/audit?action=campaign.recalibrated");
  ASSERT_EQ(audit.at("entries").size(), 1u) << audit.dump().substr(0, 600);
  const json& entry = audit.at("entries")[0];
  EXPECT_EQ(entry.at("details").at("reason"), reason);
  EXPECT_DOUBLE_EQ(entry.at("details").at("gravity_before_mps2").get<double>(), g_old);
  EXPECT_DOUBLE_EQ(entry.at("details").at("gravity_after_mps2").get<double>(), g_new);
}

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

  const auto [refused_status, refused] = run_imucal(run);
  EXPECT_EQ(refused_status, 2) << refused;
  for (const char* words : {"not started", "rate table", "T-0815", "2020-01-31", "--override-overdue"})
    EXPECT_NE(refused.find(words), std::string::npos) << words << " missing from: " << refused;
  EXPECT_EQ(refused.find("C-4711"), std::string::npos) << "the chamber is not overdue: " << refused;
  const auto [blank_status, blank] = run_imucal(run + " --override-overdue ' '");
  EXPECT_EQ(blank_status, 2) << blank;
  EXPECT_NE(blank.find("--override-overdue must say why"), std::string::npos) << blank;

  const std::string reason = "rehearsal of the overdue table on the simulated bench";
  const auto [status, out] = run_imucal(run + " --override-overdue '" + reason + "' --operator alice");
  ASSERT_EQ(status, 0) << out;
  EXPECT_NE(out.find("overridden by alice: " + reason), std::string::npos) << out;

  daemon::DaemonDb db(dir + "/data/imucald.db");
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

// Issue 35, deliverable 1: a certificate is issued when its run ends (in the order runs end, not
// the order someone first opens them), its content is frozen and hashed (and signed with the lab's
// key), and new limits, which change its verdict, issue a new certificate superseding it: the old
// one is unchanged, marked superseded and still there; the new one takes the next number. A partial
// run gets its certificate when an operator accepts it.
namespace {

// The run's transitions in the audit trail, in order from created to done, then `certificate`
// issued at the end (both from the certificates' run subscriber: this daemon has no HTTP server,
// no live feed is listened to).
void expect_transitions_then_issued(LocalDaemon& d, std::int64_t campaign, const json& certificate) {
  auto trail = d.get("/api/audit?limit=1000").at("entries").get<std::vector<json>>();
  std::sort(trail.begin(), trail.end(), [](const json& x, const json& y) { return x.at("seq") < y.at("seq"); });
  std::string state = "created";
  bool issued_after_done = false;
  for (const json& e : trail) {
    if (e.at("action") == "campaign.transition" && e.at("subject") == "campaign " + std::to_string(campaign)) {
      EXPECT_EQ(e.at("actor"), "imucald");
      EXPECT_EQ(e.at("details").at("from"), state) << e.dump();
      state = e.at("details").at("to");
    } else if (e.at("action") == "certificate.issued" && e.at("subject") == certificate.at("number")) {
      EXPECT_EQ(state, "done") << "issued before the run's transition to done";
      EXPECT_EQ(e.at("details").at("reason"), "the run ended");
      issued_after_done = state == "done";
    }
  }
  EXPECT_EQ(state, "done");
  EXPECT_TRUE(issued_after_done);
}

// `imucal verify` of a downloaded signed certificate against a public key file, as a customer runs it.
std::pair<int, std::string> verify_download(const std::string& dir, const json& download, const std::string& public_key) {
  const std::string file = dir + "/download.json";
  std::ofstream(file) << download.dump(1);
  return run_imucal("verify '" + file + "' --key '" + public_key + "'");
}

// Both downloads verified offline; a digit changed, the signature changed or another lab's key,
// each named as the check that failed.
void expect_verify_names_each_failure(const std::string& dir, const std::string& key_file, const json& first,
                                      const json& second) {
  for (const json* c : {&first, &second}) {
    const auto [status, out] = verify_download(dir, c->at("signed"), key_file + ".pub");
    EXPECT_EQ(status, 0) << out;
  }
  json digit = second.at("signed");
  digit["content"]["sequence"] = digit["content"]["sequence"].get<std::int64_t>() + 1;
  const auto [digit_status, digit_out] = verify_download(dir, digit, key_file + ".pub");
  EXPECT_EQ(digit_status, 1) << digit_out;
  EXPECT_NE(digit_out.find("NOT VERIFIED: the content hash check failed"), std::string::npos) << digit_out;
  json resigned = second.at("signed");
  std::string value = resigned["signature"]["value"];
  value[0] = value[0] == 'A' ? 'B' : 'A';
  resigned["signature"]["value"] = value;
  const auto [signature_status, signature_out] = verify_download(dir, resigned, key_file + ".pub");
  EXPECT_EQ(signature_status, 1) << signature_out;
  EXPECT_NE(signature_out.find("NOT VERIFIED: the signature check failed"), std::string::npos) << signature_out;
  signing::write_key_file(dir + "/other-lab.key", signing::generate_key_pair());
  const auto [other_status, other_out] = verify_download(dir, second.at("signed"), dir + "/other-lab.key.pub");
  EXPECT_EQ(other_status, 1) << other_out;
  EXPECT_NE(other_out.find("NOT VERIFIED: the key check failed"), std::string::npos) << other_out;
}

// The page as printed, stored once: it must be this certificate's (of `campaign`); then it never changes.
void expect_page_stored_once(LocalDaemon& d, std::int64_t campaign, const json& certificate) {
  const std::string number = certificate.at("number").get<std::string>();
  const std::string page_target = "/api/certificates/" + number + "/page";
  EXPECT_EQ(d.call("GET", page_target).status, 404);
  const std::string html = "<!doctype html><p>" + number + " " + certificate.at("content_sha256").get<std::string>() + "</p>\n";
  const auto not_it = d.call("PUT", page_target, json{{"html", "<p>" + number + "</p>"}}.dump());
  EXPECT_EQ(not_it.status, 400) << not_it.body;
  EXPECT_EQ(d.call("PUT", page_target, json{{"html", html}}.dump(), kViewerToken).status, 403);
  const auto stored = d.call("PUT", page_target, json{{"html", html}}.dump());
  ASSERT_EQ(stored.status, 201) << stored.body;
  EXPECT_EQ(json::parse(stored.body).at("sha256"), signing::sha256_hex(html));
  const auto twice = d.call("PUT", page_target, json{{"html", html + " "}}.dump());
  EXPECT_EQ(twice.status, 409) << twice.body;
  EXPECT_NE(twice.body.find("never changes"), std::string::npos) << twice.body;
  const auto page = d.call("GET", page_target, "", kViewerToken);
  EXPECT_EQ(page.status, 200);
  EXPECT_EQ(page.body, html) << "the stored bytes, unchanged";
  EXPECT_EQ(d.get(certificate_target(campaign)).at("page").at("sha256"), signing::sha256_hex(html));
}

// A partial run: no certificate until an operator accepts it, then one saying so, numbered after
// `last_sequence`.
void expect_partial_run_certified_once_accepted(LocalDaemon& d, std::int64_t last_sequence) {
  json slow = certificate_campaign("stopped early", "FOG-23");
  slow["time_scale"] = 20;
  const auto p = d.post_campaign(slow);
  ASSERT_EQ(start_overriding(d, p), 200);
  d.wait_for(p, [](const json& c) { return c.at("program_time_s").get<double>() > 0.8 * c.at("duration_s").get<double>(); });
  ASSERT_EQ(d.command(p, "stop"), 200);
  const json stopped = d.wait_final(p);
  ASSERT_FALSE(stopped.at("complete").get<bool>());
  ASSERT_TRUE(stopped.at("has_model").get<bool>()) << stopped.at("results").dump().substr(0, 600);
  const auto refused = d.call("GET", certificate_target(p));
  EXPECT_EQ(refused.status, 409);
  EXPECT_NE(refused.body.find("accept"), std::string::npos) << refused.body;
  const auto accepted = d.call("POST", "/api/campaigns/" + std::to_string(p) + "/accept",
                               json{{"reason", "stopped at 80 %: enough statics"}}.dump());
  ASSERT_EQ(accepted.status, 200) << accepted.body;
  const json cp = d.get(certificate_target(p));
  EXPECT_NE(cp.at("reason").get<std::string>().find("partial run accepted by"), std::string::npos) << cp.dump().substr(0, 400);
  EXPECT_EQ(cp.at("sequence").get<std::int64_t>(), last_sequence + 1);
  EXPECT_TRUE(cp.at("content").at("campaign").at("accepted").is_object());
}

}  // namespace

TEST(Certificate, IssuedWhenTheRunEndsFrozenSignedAndSupersededWhenLimitsChange) {
  const std::string dir = scratch_dir("certificate-issued-lab");  // not the daemon's: that one starts empty
  const std::string key_file = dir + "/lab.key";
  signing::write_key_file(key_file, signing::generate_key_pair());
  const signing::PublicKey lab_key = signing::read_public_key(key_file + ".pub");
  LocalDaemon d("certificate-issued", false, [&](daemon::DaemonConfig& c) {
    configure(c, dir + "/sequence.json");
    c.certificates.signing_key_file = key_file;
  });
  const auto a = run_campaign(d, "first", "FOG-21");
  const auto b = run_campaign(d, "second", "FOG-22");
  // Opened in the other order: numbered as the runs ended.
  const json cb = d.get(certificate_target(b));
  const json ca = d.get(certificate_target(a));
  ASSERT_TRUE(ca.contains("number")) << ca.dump();
  ASSERT_TRUE(cb.contains("number")) << cb.dump();
  EXPECT_LT(ca.at("sequence").get<std::int64_t>(), cb.at("sequence").get<std::int64_t>());
  EXPECT_EQ(ca.at("reason"), "the run ended");
  EXPECT_TRUE(ca.at("supersedes").is_null());
  EXPECT_TRUE(ca.at("superseded_by").is_null());
  expect_transitions_then_issued(d, a, ca);
  // What it states, frozen: no limits for PN-100 yet; signed over the content, with the lab's key.
  EXPECT_TRUE(ca.at("content").at("campaign").at("verdict").is_null()) << ca.at("content").at("campaign").dump();
  EXPECT_EQ(ca.at("content").at("number"), ca.at("number"));
  const signing::Verification v = signing::verify_document(ca.at("signed"), lab_key);
  EXPECT_TRUE(v.verified()) << v.message;
  EXPECT_EQ(ca.at("signed").at("content"), ca.at("content"));
  EXPECT_EQ(ca.at("signed").at("content_sha256"), ca.at("content_sha256"));
  const std::string old_number = ca.at("number");

  // Limits for the part: every certificate of it now states a verdict it did not; each is superseded.
  const json limits = {{"format", "imucal-limits/1"},
                       {"part_numbers", {{"PN-100", {{"gyro.bias_dph", {{"max_abs", 1.0}}}}}}}};
  ASSERT_EQ(d.call("PUT", "/api/limits", limits.dump()).status, 200);
  const json old_after = d.get("/api/certificates/" + old_number);
  EXPECT_EQ(old_after.at("content"), ca.at("content")) << "the issued certificate changed";
  EXPECT_EQ(old_after.at("content_sha256"), ca.at("content_sha256"));
  EXPECT_EQ(old_after.at("signed"), ca.at("signed"));
  EXPECT_EQ(old_after.at("issued"), ca.at("issued"));
  const json ca2 = d.get(certificate_target(a));
  const json cb2 = d.get(certificate_target(b));
  EXPECT_EQ(old_after.at("superseded_by"), ca2.at("number"));
  EXPECT_EQ(ca2.at("supersedes"), old_number);
  EXPECT_NE(ca2.at("reason").get<std::string>().find("acceptance limits changed by"), std::string::npos) << ca2.at("reason");
  EXPECT_EQ(ca2.at("sequence").get<std::int64_t>(), cb.at("sequence").get<std::int64_t>() + 1) << "numbered next";
  EXPECT_EQ(cb2.at("sequence").get<std::int64_t>(), ca2.at("sequence").get<std::int64_t>() + 1);
  EXPECT_TRUE(ca2.at("content").at("campaign").at("verdict").is_object()) << ca2.at("content").dump().substr(0, 600);
  EXPECT_TRUE(signing::verify_document(ca2.at("signed"), lab_key).verified());
  EXPECT_EQ(ca2.at("history").size(), 2u);
  expect_verify_names_each_failure(dir, key_file, ca, ca2);
  expect_page_stored_once(d, a, ca2);
  // The same limits again change nothing: nothing is issued.
  ASSERT_EQ(d.call("PUT", "/api/limits", limits.dump()).status, 200);
  EXPECT_EQ(d.get(certificate_target(a)).at("number"), ca2.at("number"));
  // Limits for another part number: these units' certificates are not even looked at.
  json more = limits;
  more["part_numbers"]["PN-200"] = {{"gyro.bias_dph", {{"max_abs", 0.5}}}};
  ASSERT_EQ(d.call("PUT", "/api/limits", more.dump()).status, 200);
  EXPECT_EQ(d.get(certificate_target(a)).at("number"), ca2.at("number"));
  EXPECT_EQ(d.call("GET", "/api/certificates/NO-SUCH-1").status, 404);

  expect_partial_run_certified_once_accepted(d, cb2.at("sequence").get<std::int64_t>());
}

namespace {

// `imucal audit verify DIR`: its exit status and what it printed.
std::pair<int, std::string> audit_verify(const std::string& data_dir) { return run_imucal("audit verify '" + data_dir + "'"); }

}  // namespace

// Issue 35, deliverable 3: who changed what, when, each entry chained to the one before; an edit
// or a deletion anywhere makes `imucal audit verify` fail, naming the first bad entry.
TEST(Audit, EveryChangeIsChainedAndAnEditOrADeletionIsFound) {
  std::string data_dir;
  {
    LocalDaemon d("audit", false, [&](daemon::DaemonConfig& c) { configure(c, scratch_dir("audit-site") + "/seq.json"); });
    data_dir = d.config.data_dir;
    const auto id = run_campaign(d, "audited", "FOG-31");
    // The state says done a moment before the run's end issues its certificate (the run's end
    // event follows the state it reports): read it, which waits for it or issues it.
    ASSERT_TRUE(d.get(certificate_target(id)).contains("number"));
    const json limits = {{"format", "imucal-limits/1"},
                         {"part_numbers", {{"PN-100", {{"gyro.bias_dph", {{"max_abs", 1.0}}}}}}}};
    ASSERT_EQ(d.call("PUT", "/api/limits", limits.dump()).status, 200);
    const json trail = d.get("/api/audit?limit=1000");
    EXPECT_TRUE(trail.at("intact").get<bool>()) << trail.at("check");
    std::map<std::string, int> actions;
    for (const json& e : trail.at("entries")) ++actions[e.at("action").get<std::string>()];
    EXPECT_EQ(actions["service.started"], 1);
    EXPECT_EQ(actions["campaign.created"], 1);
    EXPECT_EQ(actions["campaign.command"], 1);  // start
    EXPECT_EQ(actions["campaign.override_overdue"], 1);  // of the overdue table, by the operator
    EXPECT_GE(actions["campaign.transition"], 3);  // created -> queued -> running -> done
    EXPECT_EQ(actions["limits.replaced"], 1);
    EXPECT_EQ(actions["certificate.issued"], 2);  // at the end, and under the new limits
    EXPECT_EQ(actions["certificate.superseded"], 1);
    // Who: the operator's name on what the operator did, imucald on what the service did.
    const json mine = d.get("/api/audit?action=limits.&actor=operator");
    ASSERT_EQ(mine.at("entries").size(), 1u) << mine.dump();
    EXPECT_TRUE(mine.at("entries")[0].at("details").at("before").is_object());
    EXPECT_EQ(mine.at("entries")[0].at("details").at("after").at("part_numbers").size(), 1u);
    const json about = d.get("/api/audit?subject=campaign%20" + std::to_string(id));
    EXPECT_GE(about.at("entries").size(), 4u);
    const auto csv = d.call("GET", "/api/audit?format=csv&action=limits.");
    EXPECT_EQ(csv.status, 200);
    EXPECT_EQ(csv.body.rfind("seq,time_utc,actor,action,subject,details,sha256\r\n", 0), 0u) << csv.body.substr(0, 200);
    EXPECT_EQ(d.call("GET", "/api/audit?since=2026-01-01").status, 400);
    EXPECT_EQ(d.call("GET", "/api/audit?from=yesterday").status, 400);
  }
  const auto [ok_status, ok_text] = audit_verify(data_dir);
  EXPECT_EQ(ok_status, 0) << ok_text;
  EXPECT_NE(ok_text.find("OK: audit trail intact"), std::string::npos) << ok_text;

  // Tampered copies of the database: one entry edited, one deleted, the last one deleted.
  const auto tampered = [&](const std::string& name, const std::string& sql) {
    const std::string copy = scratch_dir("audit-" + name);
    std::filesystem::copy_file(data_dir + "/imucald.db", copy + "/imucald.db");
    storage::sql::Connection db(copy + "/imucald.db", storage::sql::Connection::Open::read_write, "test");
    db.exec("DROP TRIGGER audit_append_only; DROP TRIGGER audit_kept; " + sql);
    return copy;
  };
  // (The WAL was checkpointed when the service closed the database.)
  const auto [edited_status, edited] = audit_verify(tampered("edited", "UPDATE audit SET actor = 'mallory' WHERE seq = 4"));
  EXPECT_EQ(edited_status, 1) << edited;
  EXPECT_NE(edited.find("audit entry 4: changed after it was written"), std::string::npos) << edited;
  const auto [deleted_status, deleted] = audit_verify(tampered("deleted", "DELETE FROM audit WHERE seq = 3"));
  EXPECT_EQ(deleted_status, 1) << deleted;
  EXPECT_NE(deleted.find("audit entry 4: entries 3 to 3 before it are missing"), std::string::npos) << deleted;
  const auto [tail_status, tail] = audit_verify(tampered("tail", "DELETE FROM audit WHERE seq = (SELECT MAX(seq) FROM audit)"));
  EXPECT_EQ(tail_status, 1) << tail;
  EXPECT_NE(tail.find("entries at the end were deleted"), std::string::npos) << tail;
  EXPECT_NE(audit_verify(scratch_dir("audit-empty")).second.find("no imucald database"), std::string::npos);
}

// Issue 38, "the database away": a stand whose registry server stops runs its campaign on (the
// start's override and the audit entries wait in its journal, the status says so, the certificate
// answers 503); when the server is back the journal is replayed and the certificate issued at its
// first request. Asked until it answers, with a generous bound: no clock to beat on a loaded machine.
TEST(Registry, AStandWhoseRegistryServerIsAwayRunsOnAndCatchesUpWhenItReturns) {
  static imucaltest::PostgresServer server;
  if (!server.skip_reason().empty()) GTEST_SKIP() << server.skip_reason();
  ASSERT_TRUE(server.running()) << server.error();
  const std::string conninfo = server.create_database(imucaltest::PostgresServer::unique_name("away"));
  LocalDaemon d("registry-away", false, [&](daemon::DaemonConfig& c) {
    configure(c, scratch_dir("registry-away-unused") + "/sequence.json");
    c.registry.postgresql = conninfo;
    c.registry.stand = "stand-away";
  });
  ASSERT_TRUE(server.stop_for_a_while());
  const auto id = run_campaign(d, "away", "FOG-A");
  const json away = d.get("/api/status").at("registry");
  EXPECT_EQ(away.at("backend"), "postgresql");
  EXPECT_FALSE(away.at("reachable").get<bool>()) << away.dump();
  EXPECT_GT(away.at("pending_writes").get<std::int64_t>(), 0) << away.dump();
  const auto refused = d.call("GET", certificate_target(id));
  EXPECT_EQ(refused.status, 503) << refused.body;
  EXPECT_NE(refused.body.find("unreachable"), std::string::npos) << refused.body;

  ASSERT_TRUE(server.start_again());
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(120);
  auto reply = d.call("GET", certificate_target(id));
  while (reply.status != 200 && std::chrono::steady_clock::now() < deadline) {
    std::this_thread::sleep_for(std::chrono::milliseconds(250));
    reply = d.call("GET", certificate_target(id));
  }
  ASSERT_EQ(reply.status, 200) << reply.body;
  EXPECT_EQ(json::parse(reply.body).at("sequence"), 1);
  const json back = d.get("/api/status").at("registry");
  EXPECT_TRUE(back.at("reachable").get<bool>()) << back.dump();
  EXPECT_EQ(back.at("pending_writes"), 0) << back.dump();
  // The run's calibration, recorded at its end while the server was away, is in the unit's history.
  const json unit = d.get("/api/imus/FOG-A");
  ASSERT_EQ(unit.at("calibrations").size(), 1U) << unit.dump();
  EXPECT_EQ(unit.at("calibrations")[0].at("stand"), "stand-away");
  EXPECT_EQ(unit.at("calibrations")[0].at("state"), "done");
  EXPECT_EQ(unit.at("calibrations_counted"), 1) << unit.dump();

  daemon::PostgresRegistry registry(conninfo, "stand-away");
  EXPECT_TRUE(registry.overdue_override(id).has_value());
  const daemon::AuditChain chain = registry.audit_chain();
  const auto& trail = chain.entries;
  EXPECT_TRUE(daemon::check_audit_chain(chain).ok());
  const auto transitions = std::count_if(trail.begin(), trail.end(), [](const daemon::AuditEntry& e) {
    return e.action == "campaign.transition";
  });
  EXPECT_GE(transitions, 2);  // the run's, journaled while the server was away
  EXPECT_TRUE(d.get("/api/audit").at("intact").get<bool>());
}

// Issue 38: two stands' imucald on one PostgreSQL registry (a private server, tests/postgres_server.hpp)
// number their certificates from its sequence, one after the other, and write one audit trail;
// each stand's own SQLite database keeps none of it.
TEST(Registry, TwoStandsOnOnePostgresRegistryShareTheNumberingAndTheAuditTrail) {
  static imucaltest::PostgresServer server;
  if (!server.skip_reason().empty()) GTEST_SKIP() << server.skip_reason();
  ASSERT_TRUE(server.running()) << server.error();
  const std::string conninfo = server.create_database(imucaltest::PostgresServer::unique_name("stands"));
  const auto on_registry = [&](const std::string& stand) {
    return [&, stand](daemon::DaemonConfig& c) {
      configure(c, scratch_dir("registry-unused-" + stand) + "/sequence.json");
      c.registry.postgresql = conninfo;
      c.registry.stand = stand;
    };
  };
  LocalDaemon a("registry-stand-a", false, on_registry("stand-a"));
  LocalDaemon b("registry-stand-b", false, on_registry("stand-b"));
  const auto id_a = run_campaign(a, "on a", "FOG-A");
  const auto id_b = run_campaign(b, "on b", "FOG-B");
  const json ca = a.get(certificate_target(id_a));
  const json cb = b.get(certificate_target(id_b));
  EXPECT_EQ(ca.at("sequence"), 1) << ca.dump();
  EXPECT_EQ(cb.at("sequence"), 2) << cb.dump();
  // A number is the lab's: stand b finds stand a's certificate by it.
  EXPECT_EQ(b.call("GET", "/api/certificates/" + ca.at("number").get<std::string>()).status, 200);
  // Campaign ids are each stand's own: both ran campaign 1, each sees its own certificate.
  EXPECT_EQ(id_a, id_b);
  EXPECT_EQ(a.get(certificate_target(id_a)).at("number"), ca.at("number"));

  daemon::PostgresRegistry registry(conninfo, "test");
  EXPECT_EQ(registry.max_certificate_sequence(), 2);
  const daemon::AuditChain chain = registry.audit_chain();
  const auto& trail = chain.entries;
  EXPECT_TRUE(daemon::check_audit_chain(chain).ok());
  const auto started = std::count_if(trail.begin(), trail.end(), [](const daemon::AuditEntry& e) {
    return e.action == "service.started";
  });
  EXPECT_EQ(started, 2);
  const json listed = a.get("/api/audit");
  EXPECT_TRUE(listed.at("intact").get<bool>()) << listed.dump();

  // One unit calibrated on both stands: one history, each calibration naming its stand, read
  // from either stand.
  const auto again_b = run_campaign(b, "FOG-A again on b", "FOG-A");
  for (LocalDaemon* stand : {&a, &b}) {
    const json unit = stand->get("/api/imus/FOG-A");
    ASSERT_EQ(unit.at("calibrations").size(), 2U) << unit.dump();
    EXPECT_EQ(unit.at("calibrations")[0].at("stand"), "stand-a");
    EXPECT_EQ(unit.at("calibrations")[0].at("campaign_id"), id_a);
    EXPECT_EQ(unit.at("calibrations")[1].at("stand"), "stand-b");
    EXPECT_EQ(unit.at("calibrations")[1].at("campaign_id"), again_b);
    EXPECT_EQ(unit.at("calibrations_counted"), 2) << unit.dump();
  }
  // Limits put on one stand are the other's at once (its next run judged by them).
  const json limits = {{"format", "imucal-limits/1"},
                       {"part_numbers", {{"PN-LAB", {{"gyro.bias_dph", {{"max_abs", 5.0}}}}}}}};
  ASSERT_EQ(a.call("PUT", "/api/limits", limits.dump()).status, 200);
  const json on_b = b.get("/api/limits");
  EXPECT_TRUE(on_b.at("part_numbers").contains("PN-LAB")) << on_b.dump();
  EXPECT_EQ(on_b.at("source"), "the lab's registry");

  // The stand's own database holds no certificate of its own.
  daemon::DaemonDb own(a.config.data_dir + "/imucald.db");
  EXPECT_EQ(own.max_certificate_sequence(), 0);
  EXPECT_TRUE(own.audit_trail().empty());
}
