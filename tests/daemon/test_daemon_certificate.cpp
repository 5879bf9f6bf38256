// Calibration certificates (issue 17, deliverable 5): numbers with the site's prefix that never
// repeat (not across campaigns, not across a new data directory, not between two daemons sharing
// the sequence file), the same number every time a campaign's certificate is asked for, no number
// for a run that has not ended, a certificate issued when its run ends, frozen, signed and
// superseded, and the site gravity a certificate states, with the configuration's errors naming
// the field at fault. The reference equipment: test_daemon_equipment.cpp; the audit trail and the
// lab's registry: test_daemon_audit_registry.cpp.
#include <gtest/gtest.h>

#include <algorithm>
#include <filesystem>
#include <fstream>
#include <map>
#include <mutex>
#include <regex>
#include <thread>

#include "certificate_fixture.hpp"
#include "core/earth.hpp"
#include "daemon/production/certificates.hpp"
#include "daemon/registry/certificate_sequence.hpp"
#include "signing/signing.hpp"

using namespace imucal;
using namespace imucal::daemontest;
using imucal::daemon::CertificateSequence;
using imucal::daemon::ConfigError;
using imucal::daemon::parse_config;

namespace {

// The configuration's message for `text` (empty when it is accepted).
std::string config_error(const std::string& text) {
  try {
    parse_config(text, "test.json");
  } catch (const ConfigError& e) {
    return e.what();
  }
  return {};
}

}  // namespace

TEST(Certificate, NumbersNeverRepeatAcrossCampaignsAndDataDirectories) {
  const std::string sequence_file = scratch_dir("certificate-site") + "/sequence.json";
  std::string first_number, second_number;
  {
    LocalDaemon d("certificate-a", false, [&](daemon::DaemonConfig& c) { configure_certified_bench(c, sequence_file); });
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
    configure_certified_bench(c, sequence_file);
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

// Issue 35, deliverable 1, in part: a certificate issued with one site g, read after the
// configuration's g was corrected, says so (its content unchanged), and the unit's page lists it.
// (Superseding it: the next test.)
TEST(Certificate, ACorrectedSiteGravityIsReportedOnTheCertificatesIssuedWithTheOldOne) {
  const std::string dir = scratch_dir("gravity-corrected-lab");
  LocalDaemon d("gravity-corrected", false, [&](daemon::DaemonConfig& c) { configure_certified_bench(c, dir + "/sequence.json"); });
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
  LocalDaemon d("gravity-recalibrated", false, [&](daemon::DaemonConfig& c) { configure_certified_bench(c, dir + "/sequence.json"); });
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
  return run_imucal_cli("verify '" + file + "' --key '" + public_key + "'");
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
    configure_certified_bench(c, dir + "/sequence.json");
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
