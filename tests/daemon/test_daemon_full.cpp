// The built-in campaign `full` on the simulated bench with the navigation-grade truth: direct,
// lever-arm, navigation and evaluate in one run, stage 1, the lever arms and stage 3 online (each
// from the models before), every stage's model kept, the Schuler test of each; and one offline
// pass of `imucal calibrate --stage all` on the campaign's exported recording gives the campaign's
// model to the last bit; stage 3's model meets stage 3's limits against the truth (slow: about 6.2 h of program at 100 Hz).
#include <gtest/gtest.h>

#include <filesystem>

#include "../estimators/nav_calib_fixture.hpp"
#include "service_fixture.hpp"
#include "subprocess.hpp"
#include "tests/test_paths.hpp"

using namespace imucal;
using namespace imucal::daemontest;
namespace fs = std::filesystem;

namespace {

int run_imucal(const std::vector<std::string>& args, const fs::path& log) {
  std::vector<std::string> argv = {imucaltest::program("imucal")};
  argv.insert(argv.end(), args.begin(), args.end());
  Child child = spawn_child(argv, log.string());
  read_stdout_until(child, [](const std::string&) { return false; }, 1800);
  return wait_exit(child.pid, 60);
}

}  // namespace

TEST(DaemonFull, TheFullCampaignRunsEveryStageOnlineAndMatchesTheCommandLine) {
  // The truth by name from a truths folder (a campaign names no path): examples/truth-nav-grade.json.
  LocalDaemon d("full", false, [](daemon::DaemonConfig& c) { c.sim.truths_dir = imucaltest::source_dir() + "/examples"; });
  const std::string truth = "truth-nav-grade";
  const auto id = d.post_campaign({{"name", "lab"}, {"program", "full"}, {"truth", truth}, {"rate_hz", 100},
                                   {"time_scale", 0}});
  const json stored = d.campaign(id);
  EXPECT_EQ(stored.at("spec").at("estimators"), json({"direct", "lever-arm", "stage3"}));
  ASSERT_EQ(d.command(id, "start"), 200);
  const json c = d.wait_final(id, 3600);
  ASSERT_EQ(c.at("state"), "done") << c.dump().substr(0, 2000);
  const json& results = c.at("results");
  for (const char* stage : {"direct", "lever-arm", "stage3"}) {
    ASSERT_EQ(results.at(stage).at("status"), "done") << stage << ": " << results.at(stage).dump().substr(0, 2000);
    EXPECT_TRUE(results.at(stage).contains("model")) << stage;
  }
  // Each stage on its own part of the program.
  EXPECT_NE(results.at("direct").at("source").get<std::string>().find("'direct'"), std::string::npos);
  EXPECT_NE(results.at("lever-arm").at("source").get<std::string>().find("'lever-arm'"), std::string::npos);
  EXPECT_NE(results.at("stage3").at("source").get<std::string>().find("'navigation'"), std::string::npos);
  EXPECT_EQ(results.at("stage3").at("model").at("frame"), "body");
  // Stage 3's model against the truth: every coefficient within stage 3's limits (three times the
  // seed's 1-sigma, docs/stage3.md).
  const ImuModel truth_body = direct::to_body_frame(read_imu_model_file(imucaltest::source_dir() + "/examples/truth-nav-grade.json"));
  const ImuModel stage3 = imu_model_from_json_text(results.at("stage3").at("model").dump(), "stage 3's model");
  EXPECT_LE(navcaltest::expect_stage3_limits(truth_body, stage3), 1.0);

  // The Schuler test compares every stage's model.
  const auto eval = d.get_computed("/api/campaigns/" + std::to_string(id) + "/evaluation");
  ASSERT_EQ(eval.status, 200) << eval.body.substr(0, 500);
  std::vector<std::string> variants;
  const json evaluation = json::parse(eval.body);
  for (const auto& v : evaluation.at("variants")) variants.push_back(v.at("name").get<std::string>());
  if (variants.empty()) ADD_FAILURE() << eval.body.substr(0, 1000);
  for (const char* name : {"stage direct", "stage lever-arm", "stage stage3"})
    EXPECT_NE(std::find(variants.begin(), variants.end(), name), variants.end()) << name << " in " << json(variants).dump();

  // Offline: export, import, one pass of every stage.
  const fs::path dir = fs::path(d.config.data_dir) / "offline";
  fs::create_directories(dir);
  ASSERT_EQ(run_imucal({"export", "--db", d.run_path(c), "--out", (dir / "bundle").string()}, dir / "export.log"), 0);
  ASSERT_EQ(run_imucal({"import", (dir / "bundle").string(), "--db", (dir / "imported.db").string()}, dir / "import.log"), 0);
  ASSERT_EQ(run_imucal({"calibrate", "--db", (dir / "imported.db").string(), "--stage", "all", "--out",
                        (dir / "model.json").string()},
                       dir / "calibrate.log"),
            0);
  const auto online = d.call("GET", "/api/campaigns/" + std::to_string(id) + "/model");
  ASSERT_EQ(online.status, 200);
  EXPECT_EQ(imu_model_to_json_text(read_imu_model_file((dir / "model.json").string())),
            imu_model_to_json_text(imu_model_from_json_text(online.body, "the campaign's model")));
}
