// The production line through the API on the simulated bench (issue 17): campaigns name their
// unit, the registry lists each unit's calibrations, a stopped run is partial and counts only once
// an operator accepts it, and a unit's history exports as CSV agreeing with the models.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdlib>
#include <fstream>
#include <map>
#include <sstream>

#include "daemon/campaign_runner.hpp"
#include "service_fixture.hpp"
#include "storage/run_db.hpp"

using namespace imucal;
using namespace imucal::daemontest;

namespace {

json unit_campaign(const std::string& name, const std::string& serial, double time_scale) {
  return direct_short_calibration(
      name, {{"serial", serial}, {"part_number", "PN-100"}, {"firmware", "2.1"}, {"customer", "ACME"}}, time_scale);
}

std::vector<std::string> split(const std::string& line, char sep) {
  std::vector<std::string> out;
  std::stringstream s(line);
  std::string field;
  while (std::getline(s, field, sep)) out.push_back(field);
  if (!line.empty() && line.back() == sep) out.emplace_back();
  return out;
}

const json* find_unit(const json& list, const std::string& serial) {
  for (const json& u : list.at("imus"))
    if (u.at("serial") == serial) return &u;
  return nullptr;
}

}  // namespace

TEST(Units, RegistryHistoryPartialRunsAndAcceptance) {
  LocalDaemon d("units");
  // FOG-7 twice (the second stopped early), FOG-8 once; the stopped one runs slowly enough to stop.
  const auto a = d.post_campaign(unit_campaign("fog7-first", "FOG-7", 0));
  const auto b = d.post_campaign(unit_campaign("fog7-stopped", "FOG-7", 40));
  const auto c = d.post_campaign(unit_campaign("fog8", "FOG-8", 0));
  ASSERT_EQ(d.command(a, "start"), 200);
  ASSERT_EQ(d.wait_final(a).at("state"), "done");
  ASSERT_EQ(d.command(b, "start"), 200);
  const double duration_s = d.campaign(b).at("duration_s").get<double>();
  d.wait_for(b, [&](const json& j) { return j.at("program_time_s").get<double>() > 0.8 * duration_s; });
  ASSERT_EQ(d.command(b, "stop"), 200);
  const json stopped = d.wait_final(b);
  ASSERT_EQ(stopped.at("state"), "done");
  ASSERT_TRUE(stopped.at("has_model").get<bool>()) << stopped.at("results").dump();
  ASSERT_EQ(d.command(c, "start"), 200);
  ASSERT_EQ(d.wait_final(c).at("state"), "done");

  // Each campaign names its unit; the run file records the unit's serial.
  const json first = d.campaign(a);
  EXPECT_EQ(first.at("imu").at("serial"), "FOG-7");
  EXPECT_EQ(first.at("imu").at("customer"), "ACME");
  EXPECT_EQ(first.at("imu_serial"), "FOG-7");
  EXPECT_TRUE(first.at("complete").get<bool>());
  EXPECT_FALSE(stopped.at("complete").get<bool>());
  EXPECT_TRUE(stopped.at("accepted").is_null());
  EXPECT_EQ(d.campaign(c).at("imu_serial"), "FOG-8");

  // The unit's calibrations in time order, the stopped one partial.
  json fog7 = d.get("/api/imus/FOG-7");
  ASSERT_EQ(fog7.at("calibrations").size(), 2u) << fog7.dump().substr(0, 2000);
  EXPECT_EQ(fog7.at("part_number"), "PN-100");
  EXPECT_EQ(fog7.at("calibrations")[0].at("campaign_id"), a);
  EXPECT_EQ(fog7.at("calibrations")[0].at("program"), "direct-short");
  EXPECT_TRUE(fog7.at("calibrations")[0].at("complete").get<bool>());
  EXPECT_TRUE(fog7.at("calibrations")[0].at("verdict").is_null());
  EXPECT_EQ(fog7.at("calibrations")[1].at("campaign_id"), b);
  EXPECT_FALSE(fog7.at("calibrations")[1].at("complete").get<bool>());
  EXPECT_FALSE(fog7.at("calibrations")[1].at("counts").get<bool>());
  EXPECT_EQ(fog7.at("calibrations_counted"), 1);
  EXPECT_EQ(d.call("GET", "/api/imus/FOG-9").status, 404);

  // The registry: the stopped run does not count until accepted.
  json units = d.get("/api/imus");
  ASSERT_NE(find_unit(units, "FOG-7"), nullptr) << units.dump();
  ASSERT_NE(find_unit(units, "FOG-8"), nullptr) << units.dump();
  EXPECT_EQ(find_unit(units, "FOG-7")->at("calibrations"), 1);
  EXPECT_EQ(find_unit(units, "FOG-7")->at("last_calibration").at("campaign_id"), a);
  EXPECT_EQ(find_unit(units, "FOG-8")->at("calibrations"), 1);
  EXPECT_EQ(find_unit(units, "FOG-8")->at("part_number"), "PN-100");

  // Acceptance: operators only, with a reason, only of a partial run.
  const std::string accept = "/api/campaigns/" + std::to_string(b) + "/accept";
  EXPECT_EQ(d.call("POST", accept, R"({"reason": "enough positions"})", kViewerToken).status, 403);
  EXPECT_EQ(d.call("POST", accept, R"({})").status, 400);
  EXPECT_EQ(d.call("POST", accept, R"({"reason": "  "})").status, 400);
  EXPECT_EQ(d.call("POST", "/api/campaigns/" + std::to_string(a) + "/accept", R"({"reason": "x"})").status, 409);
  const auto accepted = d.call("POST", accept, R"({"reason": "stopped after the last rate segment"})");
  ASSERT_EQ(accepted.status, 200) << accepted.body;
  EXPECT_EQ(json::parse(accepted.body).at("accepted").at("reason"), "stopped after the last rate segment");
  units = d.get("/api/imus");
  EXPECT_EQ(find_unit(units, "FOG-7")->at("calibrations"), 2);
  EXPECT_EQ(find_unit(units, "FOG-7")->at("last_calibration").at("campaign_id"), b);
  fog7 = d.get("/api/imus/FOG-7");
  EXPECT_FALSE(fog7.at("calibrations")[1].at("complete").get<bool>());  // still partial, but counted
  EXPECT_TRUE(fog7.at("calibrations")[1].at("counts").get<bool>());
  EXPECT_EQ(fog7.at("calibrations")[1].at("accepted").at("reason"), "stopped after the last rate segment");

  // The history as CSV: one row per calibration, its values those of the models.
  const auto csv = d.call("GET", "/api/imus/FOG-7/history.csv");
  ASSERT_EQ(csv.status, 200);
  EXPECT_EQ(csv.content_type.rfind("text/csv", 0), 0u);
  std::vector<std::string> lines = split(csv.body, '\n');
  while (!lines.empty() && lines.back().empty()) lines.pop_back();
  ASSERT_EQ(lines.size(), 3u) << csv.body.substr(0, 2000);
  const auto header = split(lines[0], ',');
  std::map<std::string, std::size_t> col;
  for (std::size_t i = 0; i < header.size(); ++i) col[header[i]] = i;
  ASSERT_TRUE(col.count("gyro.bias_dph.x")) << lines[0];
  ASSERT_TRUE(col.count("gyro.bias_dph.x.sigma")) << lines[0];
  ASSERT_TRUE(col.count("accel.scale_ppm.z")) << lines[0];
  const std::int64_t ids[] = {a, b};
  for (std::size_t r = 0; r < 2; ++r) {
    const auto row = split(lines[r + 1], ',');
    ASSERT_EQ(row.size(), header.size()) << lines[r + 1];
    EXPECT_EQ(std::stoll(row[col.at("campaign_id")]), ids[r]);
    const json model = json::parse(d.call("GET", "/api/campaigns/" + std::to_string(ids[r]) + "/model").body);
    EXPECT_DOUBLE_EQ(std::strtod(row[col.at("gyro.bias_dph.x")].c_str(), nullptr),
                     model.at("gyro").at("bias_dph")[0].get<double>());
    EXPECT_DOUBLE_EQ(std::strtod(row[col.at("accel.scale_ppm.z")].c_str(), nullptr),
                     model.at("accel").at("scale_ppm")[2].get<double>());
    ASSERT_TRUE(model.contains("sigma"));
    EXPECT_DOUBLE_EQ(std::strtod(row[col.at("gyro.bias_dph.x.sigma")].c_str(), nullptr),
                     model.at("sigma").at("gyro").at("bias_dph")[0].get<double>());
  }
  EXPECT_EQ(split(lines[2], ',')[col.at("complete")], "false");
  EXPECT_EQ(split(lines[2], ',')[col.at("counts")], "true");

  // The two calibrations side by side, the change since the previous one and the repeatability
  // agree with the two models.
  auto model_of = [&](std::int64_t id) {
    return json::parse(d.call("GET", "/api/campaigns/" + std::to_string(id) + "/model").body);
  };
  const json ma = model_of(a), mb = model_of(b);
  const double xa = ma.at("gyro").at("bias_dph")[0], xb = mb.at("gyro").at("bias_dph")[0];
  const double sa = ma.at("sigma").at("gyro").at("bias_dph")[0], sb = mb.at("sigma").at("gyro").at("bias_dph")[0];
  const json cmp = d.get("/api/compare?a=" + std::to_string(a) + "&b=" + std::to_string(b));
  ASSERT_TRUE(cmp.contains("coefficients")) << cmp.dump().substr(0, 1000);
  EXPECT_EQ(cmp.at("a").at("campaign_id"), a);
  EXPECT_EQ(cmp.at("b").at("serial"), "FOG-7");
  const json* cx = nullptr;
  for (const json& r : cmp.at("coefficients"))
    if (r.at("key") == "gyro.bias_dph.x") cx = &r;
  ASSERT_NE(cx, nullptr);
  EXPECT_DOUBLE_EQ(cx->at("difference").get<double>(), xb - xa);
  EXPECT_DOUBLE_EQ(cx->at("combined_sigma").get<double>(), std::hypot(sa, sb));
  EXPECT_EQ(cx->at("significant").get<bool>(), std::abs(xb - xa) > 3 * std::hypot(sa, sb));
  EXPECT_EQ(d.call("GET", "/api/compare?a=" + std::to_string(a)).status, 400);
  EXPECT_EQ(d.call("GET", "/api/compare?a=" + std::to_string(a) + "&b=999").status, 404);
  fog7 = d.get("/api/imus/FOG-7");
  const json& change = fog7.at("calibrations")[1].at("change");
  EXPECT_EQ(change.at("since_campaign_id"), a);
  EXPECT_DOUBLE_EQ(change.at("in_sigmas").at("gyro.bias_dph.x").get<double>(), cx->at("in_sigmas").get<double>());
  EXPECT_TRUE(fog7.at("calibrations")[0].at("change").is_null());
  const json& rep = fog7.at("repeatability").at("gyro.bias_dph.x");
  EXPECT_EQ(rep.at("n"), 2);
  EXPECT_NEAR(rep.at("std").get<double>(), std::abs(xb - xa) / std::sqrt(2.0), 1e-12 * (1 + std::abs(xa)));

  // Acceptance limits for PN-100: none yet, so no verdict; limits twice the larger of the two
  // runs' values and sigmas pass both; one coefficient's limit made tighter than run a's value
  // fails a on it, naming why.
  EXPECT_TRUE(d.campaign(a).at("verdict").is_null());
  auto twice_the_larger = [&](const char* triad, const char* key) {
    double value = 0, sigma = 0;
    for (const json* m : {&ma, &mb})
      for (int i = 0; i < 3; ++i) {
        value = std::max(value, std::abs(m->at(triad).at(key)[i].get<double>()));
        sigma = std::max(sigma, m->at("sigma").at(triad).at(key)[i].get<double>());
      }
    return json{{"max_abs", 2 * value}, {"max_sigma", 2 * sigma}};
  };
  json limits = {{"format", "imucal-limits/1"},
                 {"part_numbers",
                  {{"PN-100",
                    {{"gyro.bias_dph", twice_the_larger("gyro", "bias_dph")},
                     {"gyro.scale_pos_ppm", twice_the_larger("gyro", "scale_pos_ppm")},
                     {"accel.bias_mps2", twice_the_larger("accel", "bias_mps2")}}}}}};
  EXPECT_EQ(d.call("PUT", "/api/limits", limits.dump(), kViewerToken).status, 403);
  json bad = limits;
  bad["part_numbers"]["PN-100"]["gyro.bias"] = {{"max_abs", 1}};
  auto r = d.call("PUT", "/api/limits", bad.dump());
  EXPECT_EQ(r.status, 400);
  EXPECT_NE(r.body.find("gyro.bias"), std::string::npos) << r.body;
  EXPECT_TRUE(d.get("/api/limits").at("part_numbers").empty());  // nothing changed
  r = d.call("PUT", "/api/limits", limits.dump());
  ASSERT_EQ(r.status, 200) << r.body;
  for (const std::int64_t id : {a, b}) {
    const json v = d.campaign(id).at("verdict");
    ASSERT_FALSE(v.is_null());
    EXPECT_TRUE(v.at("pass").get<bool>()) << v.dump();
    EXPECT_EQ(v.at("part_number"), "PN-100");
    EXPECT_EQ(v.at("coefficients").size(), 9u);
  }
  EXPECT_TRUE(find_unit(d.get("/api/imus"), "FOG-7")->at("pass").get<bool>());
  limits["part_numbers"]["PN-100"]["gyro.bias_dph.x"] = {{"max_abs", std::abs(xa) / 2}};
  ASSERT_EQ(d.call("PUT", "/api/limits", limits.dump()).status, 200);
  const json fail = d.campaign(a).at("verdict");
  EXPECT_FALSE(fail.at("pass").get<bool>());
  EXPECT_EQ(fail.at("failures"), 1);
  for (const json& limited : fail.at("coefficients"))
    if (limited.at("key") == "gyro.bias_dph.x") {
      EXPECT_FALSE(limited.at("pass").get<bool>());
      EXPECT_NE(limited.at("reason").get<std::string>().find("|value|"), std::string::npos) << limited;
    } else {
      EXPECT_TRUE(limited.at("pass").get<bool>()) << limited;
    }
  fog7 = d.get("/api/imus/FOG-7");
  EXPECT_FALSE(fog7.at("calibrations")[0].at("verdict").at("pass").get<bool>());
  EXPECT_EQ(fog7.at("limits"), "limits.json");
  // The limits outlive the daemon: the file is in the data directory.
  std::ifstream saved(d.config.data_dir + "/limits.json");
  ASSERT_TRUE(saved.good());
  EXPECT_EQ(json::parse(saved).at("part_numbers").at("PN-100").at("gyro.bias_dph.x").at("max_abs"), std::abs(xa) / 2);
}

TEST(Units, ModelDownloadsHaveTheirOwnFileNames) {
  LocalDaemon d("units-downloads");
  const auto id = d.post_campaign(unit_campaign("names", "FOG-1", 0));
  ASSERT_EQ(d.command(id, "start"), 200);
  ASSERT_EQ(d.wait_final(id).at("state"), "done");
  auto disposition = [&](const std::string& query) {
    const auto r = d.call("GET", "/api/campaigns/" + std::to_string(id) + "/model" + query);
    EXPECT_EQ(r.status, 200) << r.body;
    for (const auto& [k, v] : r.headers)
      if (k == "Content-Disposition") return v;
    return std::string();
  };
  const std::string base = "campaign-" + std::to_string(id);
  EXPECT_NE(disposition("").find(base + "-model-instrument.json"), std::string::npos) << disposition("");
  EXPECT_NE(disposition("?frame=body").find(base + "-model-body.json"), std::string::npos);
  EXPECT_NE(disposition("?stage=direct&frame=body").find(base + "-direct-model-body.json"), std::string::npos);
}

TEST(Units, AnInvalidUnitIsRefusedWithItsProblem) {
  LocalDaemon d("units-invalid");
  json campaign = unit_campaign("bad", "FOG/1", 0);
  auto r = d.call("POST", "/api/campaigns", campaign.dump());
  EXPECT_EQ(r.status, 422) << r.body;
  EXPECT_NE(r.body.find("campaign.imu.serial"), std::string::npos) << r.body;
  campaign["imu"] = {{"part_number", "PN-1"}};
  r = d.call("POST", "/api/campaigns", campaign.dump());
  EXPECT_NE(r.status, 201) << r.body;
  EXPECT_NE(r.body.find("serial"), std::string::npos) << r.body;
  campaign["imu"] = {{"serial", "FOG-2"}, {"colour", "red"}};
  r = d.call("POST", "/api/campaigns", campaign.dump());
  EXPECT_NE(r.status, 201) << r.body;
  EXPECT_NE(r.body.find("colour"), std::string::npos) << r.body;
}

// A database of schema version 1 (before units) opens, keeps its campaigns and gains the columns:
// a run that ended done at its program's end counts as complete, one stopped early does not.
TEST(Units, AVersion1DatabaseIsMigrated) {
  const std::string dir = scratch_dir("units-migration");
  const std::string path = dir + "/imucald.db";
  const char* v1 = R"sql(
CREATE TABLE campaign(id INTEGER PRIMARY KEY, name TEXT NOT NULL, spec_json TEXT NOT NULL,
  program_label TEXT NOT NULL, duration_s REAL NOT NULL, state TEXT NOT NULL, created_ms INTEGER NOT NULL,
  started_ms INTEGER, ended_ms INTEGER, checkpoint_segment INTEGER, checkpoint_s REAL,
  program_time_s REAL NOT NULL DEFAULT 0, frames INTEGER NOT NULL DEFAULT 0, lost_frames INTEGER NOT NULL DEFAULT 0,
  bad_frames INTEGER NOT NULL DEFAULT 0, run_db TEXT NOT NULL DEFAULT '', model_json TEXT, results_json TEXT,
  estimators_json TEXT, error TEXT);
INSERT INTO campaign(name, spec_json, program_label, duration_s, state, created_ms, program_time_s)
  VALUES ('whole', '{}', 'direct-short', 100, 'done', 1, 100), ('stopped', '{}', 'direct-short', 100, 'done', 2, 60);
PRAGMA user_version=1;
)sql";
  {
    storage::sql::Connection db(path, storage::sql::Connection::Open::create, "test database");
    db.exec(v1);
  }

  daemon::DaemonDb migrated(path);
  const auto whole = migrated.campaign(1);
  const auto stopped = migrated.campaign(2);
  ASSERT_TRUE(whole && stopped);
  EXPECT_EQ(whole->name, "whole");
  EXPECT_EQ(whole->complete, true);
  EXPECT_EQ(stopped->complete, false);
  EXPECT_FALSE(whole->imu_serial.has_value());
  EXPECT_TRUE(migrated.unit_campaigns(std::nullopt).empty());
  // New campaigns name their unit.
  const auto id = migrated.insert_campaign("new", "{}", "direct-short", 100, "test", daemon::CampaignUnit{"FOG-1", "PN"});
  EXPECT_EQ(migrated.unit_campaigns(std::string("FOG-1")).at(0).id, id);
}

// `imucal campaign run` takes the same `imu` key: the run file records the unit's serial and the
// data directory's database keeps the unit.
TEST(Units, CampaignRunFilesNameTheirUnit) {
  const std::string dir = scratch_dir("units-campaign-run");
  const std::string file = dir + "/campaign.json";
  {
    std::ofstream out(file);
    out << unit_campaign("from a file", "FOG-FILE-3", 0).dump();
  }
  daemon::CampaignRunOptions options;
  options.data_dir = dir + "/data";
  options.progress = false;
  const auto r = daemon::run_campaign_file(file, options);
  ASSERT_EQ(r.exit_code, 0) << r.error;
  EXPECT_EQ(storage::RunDb::open(r.run_db, storage::OpenMode::Read).meta().imu_serial, "FOG-FILE-3");
  daemon::DaemonDb db(options.data_dir + "/imucald.db");
  const auto rows = db.unit_campaigns(std::string("FOG-FILE-3"));
  ASSERT_EQ(rows.size(), 1u);
  EXPECT_EQ(rows[0].imu_part_number, "PN-100");
  EXPECT_EQ(rows[0].complete, true);
}

// Issue 19, item 4: the run's test report (GET /api/campaigns/{id}/report): per test its figures
// with their uncertainty and conditions, the run's conditions, and the verdict against the part
// number's limits on the figures that have them.
TEST(Units, TheTestReportStatesFiguresConditionsAndTheVerdict) {
  LocalDaemon d("report");
  const json limits = {{"format", "imucal-limits/1"},
                       {"part_numbers", {{"PN-REPORT", {{"accel.k2_ug_per_g2", {{"max_abs", 100}, {"max_sigma", 5}}}}}}}};
  ASSERT_EQ(d.call("PUT", "/api/limits", limits.dump()).status, 200);
  json truth = noisy_truth();
  truth["accel"]["k2_ug_per_g2"] = {30, -45, 22};
  truth["turn_on"] = {{"gyro", {{"warm_up_dph", {0.05, -0.03, 0.06}}, {"warm_up_time_constant_s", {300, 400, 480}}}}};
  const auto id = d.post_campaign({{"name", "report"}, {"program", {"warm-up-short", "tumble-short"}}, {"rate_hz", 10},
                                   {"time_scale", 0}, {"truth", truth},
                                   {"imu", {{"serial", "FOG-REPORT"}, {"part_number", "PN-REPORT"}}}});
  EXPECT_EQ(d.campaign(id).at("spec").at("estimators"), json({"tumble", "warm-up"}));  // pipeline order
  ASSERT_EQ(d.command(id, "start"), 200);
  ASSERT_EQ(d.wait_final(id, 300).at("state"), "done");
  const auto r = d.call("GET", "/api/campaigns/" + std::to_string(id) + "/report");
  ASSERT_EQ(r.status, 200) << r.body;
  const json report = json::parse(r.body);
  EXPECT_EQ(report.at("format"), "imucal-test-report/1");
  EXPECT_EQ(report.at("unit").at("serial"), "FOG-REPORT");
  const json& c = report.at("conditions");
  EXPECT_EQ(c.at("rate_hz"), 10);
  EXPECT_NEAR(c.at("gravity").at("value_mps2").get<double>(), 9.8, 0.05);
  EXPECT_TRUE(c.at("simulated").get<bool>());
  EXPECT_NEAR(c.at("temperatures").at("chamber_C").at("mean").get<double>(), 25.0, 3.0);
  std::map<std::string, json> tests;
  for (const json& t : report.at("tests")) tests[t.at("test").get<std::string>()] = t;
  ASSERT_TRUE(tests.count("tumble") && tests.count("warm-up")) << report.dump(1).substr(0, 2000);
  EXPECT_EQ(tests.at("tumble").at("conditions").at("positions"), 24);
  EXPECT_NE(tests.at("tumble").at("standard").get<std::string>().find("1293"), std::string::npos);
  bool judged = false;
  for (const json& f : tests.at("tumble").at("figures")) {
    EXPECT_GT(f.at("u").get<double>(), 0.0) << f.dump();
    if (f.at("key") == "accel.k2_ug_per_g2.y") {
      judged = true;
      EXPECT_NEAR(f.at("value").get<double>(), -45.0, 3.0 * f.at("u").get<double>()) << f.dump();
      EXPECT_TRUE(f.at("pass").get<bool>()) << f.dump();
      EXPECT_EQ(f.at("limit_value"), 100);
    }
  }
  EXPECT_TRUE(judged) << "the K2 figure carries its verdict";
  EXPECT_TRUE(report.at("verdict").at("pass").get<bool>());
  int transients = 0;
  for (const json& f : tests.at("warm-up").at("figures"))
    transients += f.at("key").get<std::string>().find(".time_constant_s") != std::string::npos;
  EXPECT_EQ(transients, 3) << "the three gyros warm up; the accelerometers do not";
  EXPECT_EQ(d.call("GET", "/api/campaigns/999/report").status, 404);
}

// Issue 35, deliverable 5: a `direct` run's report lists every figure its stage estimated, and a
// FAIL names its coefficients: those outside their limits and those limited but not determined.
TEST(Units, TheDirectReportListsEveryFigureAndAFailNamesItsCoefficients) {
  LocalDaemon d("report-direct");
  const json limits = {{"format", "imucal-limits/1"},
                       {"part_numbers", {{"PN-DIRECT", {{"gyro.bias_dph.y", {{"max_abs", 1e-9}}},
                                                        {"gyro.delay_us", {{"max_abs", 10}}},
                                                        {"accel.bias_mps2", {{"max_abs", 1.0}}}}}}}};
  ASSERT_EQ(d.call("PUT", "/api/limits", limits.dump()).status, 200);
  const auto id = d.post_campaign({{"name", "direct report"}, {"program", "direct-short"}, {"rate_hz", 20},
                                   {"time_scale", 0}, {"truth", noisy_truth()}, {"estimators", {"direct"}},
                                   {"imu", {{"serial", "FOG-DIRECT"}, {"part_number", "PN-DIRECT"}}}});
  ASSERT_EQ(d.command(id, "start"), 200);
  ASSERT_EQ(d.wait_final(id, 300).at("state"), "done");
  const json detail = d.campaign(id);
  std::set<std::string> estimated;
  for (const auto& [key, pair] : detail.at("results").at("direct").at("estimates").items())
    if (pair.at(1).get<double>() > 0) estimated.insert(key);
  EXPECT_EQ(estimated.size(), 27u);  // stage 1: biases, scale factors and axis angles of both triads
  const json report = d.get("/api/campaigns/" + std::to_string(id) + "/report");
  std::set<std::string> listed;
  for (const json& t : report.at("tests"))
    if (t.at("test") == "direct")
      for (const json& f : t.at("figures")) {
        listed.insert(f.at("key").get<std::string>());
        EXPECT_GT(f.at("u").get<double>(), 0.0) << f.dump();
      }
  EXPECT_EQ(listed, estimated);
  const json& verdict = report.at("verdict");
  EXPECT_FALSE(verdict.at("pass").get<bool>());
  std::map<std::string, std::string> failed;
  for (const json& f : verdict.at("failed")) failed[f.at("key").get<std::string>()] = f.at("reason").get<std::string>();
  EXPECT_EQ(failed.size(), 4u) << verdict.dump();  // gyro bias y; the three delays
  EXPECT_TRUE(failed.contains("gyro.bias_dph.y")) << verdict.dump();
  for (const char* axis : {"x", "y", "z"}) {
    EXPECT_EQ(failed[std::string("gyro.delay_us.") + axis], "not determined by this run") << verdict.dump();
    EXPECT_FALSE(failed.contains(std::string("accel.bias_mps2.") + axis));
  }
  EXPECT_EQ(verdict.at("failures").get<int>(), 4);
}
