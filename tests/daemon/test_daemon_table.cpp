// The table's certificate in the daemon's configuration (issue 34): read beside the table's limits,
// its problems listed with the rest, and written into every run's meta; the simulated bench moves
// with its geometry.
#include <gtest/gtest.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <thread>

#include "core/units.hpp"
#include "service_fixture.hpp"
#include "storage/run_db.hpp"

using namespace imucal;
using namespace imucal::daemontest;

namespace {

const char* kTableConfig = R"({"table": {
  "limits": {"middle": {"rate_dps": 200}},
  "geometry": {"outer_tilt_arcsec": [2.0, 1.2], "middle_axis_arcsec": [3.0, -1.5], "inner_axis_arcsec": [2.1, -3.0],
               "encoder_error_arcsec": {"outer": [[1, 1.0, 17.2], [2, 0.5, 34.4]], "middle": [[1, 1.0, 63.0]]}},
  "sigma": {"outer_tilt_arcsec": [0.2, 0.2]},
  "certificate": "TBL-7 of 2026-03-01"}})";

}  // namespace

TEST(Config, TheTablesCertificateStandsBesideItsLimits) {
  const daemon::DaemonConfig c = daemon::parse_config(kTableConfig, "test");
  EXPECT_DOUBLE_EQ(c.table_limits.axis[1].rate_dps, 200.0);
  const auto& certificate = c.table_certificate;
  ASSERT_TRUE(certificate);
  const auto& geometry = certificate->geometry;
  ASSERT_TRUE(geometry && certificate->sigma);
  EXPECT_DOUBLE_EQ(geometry->outer_tilt_rad[0], 2.0 * units::kArcsecToRad);
  EXPECT_EQ(geometry->encoder_error[0].size(), 2u);
  EXPECT_EQ(c.table_certificate->certificate, "TBL-7 of 2026-03-01");
  EXPECT_FALSE(daemon::parse_config("{}", "test").table_certificate.has_value());
  try {
    daemon::parse_config(R"({"table": {"geometry": {"outer_tilt_arcsec": [2, "x"]}}, "typo": 1})", "cfg.json");
    FAIL() << "accepted a bad table geometry";
  } catch (const daemon::ConfigError& e) {
    const std::string m = e.what();
    EXPECT_NE(m.find("config.table.geometry.outer_tilt_arcsec[1]: must be a number"), std::string::npos) << m;
    EXPECT_NE(m.find("unknown key \"typo\""), std::string::npos) << m;  // listed with the rest
  }
}

TEST(Sequencer, ARunRecordsTheTablesCertificate) {
  const daemon::DaemonConfig from_file = daemon::parse_config(kTableConfig, "test");
  LocalDaemon d("table", false, [&](daemon::DaemonConfig& c) { c.table_certificate = from_file.table_certificate; });
  const json spec = {{"name", "table"}, {"program", "direct-short"}, {"rate_hz", 50}, {"seed", 3},
                     {"time_scale", 0},  {"truth", noisy_truth()},   {"estimators", {"direct"}}};
  const auto id = d.post_campaign(spec);
  ASSERT_EQ(d.command(id, "start"), 200);
  const json c = d.wait_final(id);
  ASSERT_EQ(c.at("state"), "done") << c.dump();
  const auto run = storage::RunDb::open(d.run_path(c), storage::OpenMode::Read);
  const RecordingMeta meta = run.meta();
  ASSERT_TRUE(meta.table && meta.table->geometry);
  EXPECT_EQ(meta.table->certificate, "TBL-7 of 2026-03-01");
  // The simulated bench moved with the geometry: its encoders read the true angles with their errors.
  const std::vector<ImuFrame> frames = run.read_frames();
  ASSERT_FALSE(frames.empty());
  const table::TableKinematics k = table_kinematics(meta);
  const Eigen::Vector3d enc_rad = frames.front().table_deg * units::kDegToRad;
  EXPECT_GT((k.true_angles_rad(enc_rad) - enc_rad).cwiseAbs().maxCoeff(), 0.1 * units::kArcsecToRad);
  EXPECT_EQ(c.at("results").at("direct").at("status"), "done");
  // The model the certificate is printed from (GET .../model) carries stage 1's budget: the
  // certified tilt's contribution beside the fit's own, the site's g (normal gravity here), and
  // its sigma the root-sum-square of them (the certificate's u; U = 2u).
  const json model = d.get("/api/campaigns/" + std::to_string(id) + "/model");
  ASSERT_TRUE(model.contains("budget")) << model.dump().substr(0, 300);
  const json& budget = model.at("budget");
  for (const char* source : {"type_a", "table.outer_tilt_arcsec", "site.gravity_mps2"})
    EXPECT_TRUE(budget.contains(source)) << source << " missing from " << budget.dump().substr(0, 300);
  double sum_sq = 0.0;
  for (const auto& [source, set] : budget.items()) {
    const double x = set.at("gyro").at("bias_dph").at(0).get<double>();
    sum_sq += x * x;
  }
  EXPECT_NEAR(std::sqrt(sum_sq), model.at("sigma").at("gyro").at("bias_dph").at(0).get<double>(), 1e-9);
  EXPECT_GT(budget.at("table.outer_tilt_arcsec").at("accel").at("bias_mps2").at(0).get<double>(), 0.0);
}

// The builder's prediction on this bench (issue 34): POST /api/campaigns/plan simulates the runs
// with the configured table certificate, so stage 1's budget has the table's sources, each
// coefficient its dominant one, and the requirements the certified tilt.
TEST(Plan, TheBuildersPredictionCarriesTheTablesCertificate) {
  const daemon::DaemonConfig from_file = daemon::parse_config(kTableConfig, "test");
  LocalDaemon d("table-plan", false, [&](daemon::DaemonConfig& c) { c.table_certificate = from_file.table_certificate; });
  const std::string body =
      R"({"name": "p", "program": "direct-short", "rate_hz": 20, "plan": {"arw_deg_rth": 0.0005, "vrw_mps_rth": 0.002}})";
  daemon::HttpReply r = d.call("POST", "/api/campaigns/plan", body);
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(120);
  while (r.status == 202 && std::chrono::steady_clock::now() < deadline) {
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
    r = d.call("POST", "/api/campaigns/plan", body);
  }
  ASSERT_EQ(r.status, 200) << r.body;
  const json direct = json::parse(r.body).at("stages").at("direct");
  ASSERT_TRUE(direct.contains("budget")) << direct.dump().substr(0, 300);
  EXPECT_TRUE(direct.at("budget").at("accel.bias_mps2.x").at("contributions").contains("table.outer_tilt_arcsec"));
  const json& sources = direct.at("requirements").at("sources");
  const auto tilt = std::find_if(sources.begin(), sources.end(),
                                 [](const json& s) { return s.at("source") == "table.outer_tilt_arcsec"; });
  ASSERT_NE(tilt, sources.end()) << sources.dump();
  EXPECT_NEAR(tilt->at("sigma").get<double>(), 0.2, 1e-9);  // the certificate's
  EXPECT_GT(tilt->at("alone").at("max_sigma").get<double>(), 0.0);
}
