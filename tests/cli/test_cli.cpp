// imucal end to end: simulate, calibrate, navigate, export, import, keygen and verify, and clear
// errors on bad input.
#include <array>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <map>
#include <sstream>
#include <string>

#include <sys/wait.h>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "core/imu_model.hpp"
#include "core/units.hpp"
#include "signing/signing.hpp"
#include "storage/run_db.hpp"
#include "tests/test_paths.hpp"

namespace fs = std::filesystem;

namespace {

struct CliRun {
  int status;
  std::string output;  // stdout and stderr together
};

CliRun run(const std::string& args) {
  const std::string cmd = imucaltest::program("imucal") + " " + args + " 2>&1";
  CliRun r{0, {}};
  FILE* p = popen(cmd.c_str(), "r");
  std::array<char, 4096> buf{};
  while (std::fgets(buf.data(), buf.size(), p)) r.output += buf.data();
  r.status = pclose(p);
  return r;
}

fs::path fresh_dir(const std::string& name) {
  const fs::path d = fs::path(imucaltest::test_tmp_dir()) / name;
  fs::remove_all(d);
  fs::create_directories(d);
  return d;
}

}  // namespace

TEST(Cli, HelpAndBadArguments) {
  EXPECT_EQ(run("--help").status, 0);
  for (const char* sub : {"simulate", "navigate", "calibrate", "export", "import", "evaluate", "keygen", "verify", "audit verify",
                          "registry init", "registry migrate"})
    EXPECT_EQ(run(std::string(sub) + " --help").status, 0) << sub;
  const CliRun bad = run("simulate --program direct --db x.db --rate -5");
  EXPECT_NE(bad.status, 0);
  EXPECT_NE(bad.output.find("--rate"), std::string::npos) << bad.output;
  const CliRun unknown = run("simulate --program no-such --db /tmp/never.db");
  EXPECT_NE(unknown.status, 0);
  EXPECT_NE(unknown.output.find("neither a built-in"), std::string::npos) << unknown.output;
}

// Mistakes in the words of a command line: exit 2, the unknown word named first, the nearest known
// one offered (docs/cli.md, docs/daemon.md).
TEST(Cli, UnknownWordsAreNamedFirstAndExitWithStatusTwo) {
  const auto exit_status = [](const CliRun& r) { return WIFEXITED(r.status) ? WEXITSTATUS(r.status) : -1; };
  CliRun r = run("calibrat --db x.db");
  EXPECT_EQ(exit_status(r), 2) << r.output;
  EXPECT_NE(r.output.find("unknown subcommand 'calibrat'; did you mean 'calibrate'?"), std::string::npos) << r.output;
  // The typo is reported, not the missing database beside it.
  r = run("calibrate --db /no/such/run.db --stge all");
  EXPECT_EQ(exit_status(r), 2) << r.output;
  EXPECT_NE(r.output.find("unknown option '--stge'; did you mean '--stage'?"), std::string::npos) << r.output;
  EXPECT_EQ(r.output.find("such"), std::string::npos) << r.output;
  // Any other command-line error: 2 as well, with CLI11's words.
  r = run("simulate --program direct --db x.db --rate -5");
  EXPECT_EQ(exit_status(r), 2) << r.output;
  r = run("");
  EXPECT_EQ(exit_status(r), 2) << r.output;
  // imucald follows the same rule.
  const auto daemon = [](const std::string& args) {
    CliRun d{0, {}};
    FILE* p = popen((imucaltest::program("imucald") + " " + args + " 2>&1").c_str(), "r");
    std::array<char, 4096> buf{};
    while (std::fgets(buf.data(), buf.size(), p)) d.output += buf.data();
    d.status = pclose(p);
    return d;
  };
  r = daemon("--bogus");
  EXPECT_EQ(exit_status(r), 2) << r.output;
  EXPECT_NE(r.output.find("imucald: unknown option '--bogus'"), std::string::npos) << r.output;
  r = daemon("--devies sim");
  EXPECT_EQ(exit_status(r), 2) << r.output;
  EXPECT_NE(r.output.find("did you mean '--devices'?"), std::string::npos) << r.output;
  r = daemon("--devices real");
  EXPECT_EQ(exit_status(r), 2) << r.output;
  EXPECT_EQ(exit_status(daemon("--help")), 0);
}

TEST(Cli, ProgramOutsideTheLimitsIsRefusedWithTheSegment) {
  const fs::path d = fresh_dir("cli-limits");
  std::ofstream(d / "fast.json") << R"({"name":"fast","segments":[{"type":"hold","duration_s":1},
    {"type":"rate","name":"spin","axis":"inner","rate_dps":500,"duration_s":10,"accel_dps2":200}]})";
  const CliRun r = run("simulate --program " + (d / "fast.json").string() + " --db " + (d / "x.db").string());
  EXPECT_NE(r.status, 0);
  EXPECT_NE(r.output.find("segment 'spin'"), std::string::npos) << r.output;
  EXPECT_FALSE(fs::exists(d / "x.db")) << "nothing is recorded for a refused program";
}

// compare shows every key of the model: the nonlinear terms too, where the estimate or the truth
// has them, and no row for a term neither has.
TEST(Cli, CompareShowsTheNonlinearTerms) {
  const fs::path d = fresh_dir("cli-compare");
  std::ofstream(d / "truth.json") << R"({"format":"imucal-imu-model/1",
    "gyro":{"scale_nonlinear_ppm":{"x":[0,0,0.2]},"g_sensitivity_dph_per_g":[[0,0,0.004],[0,0,0],[0,0,0]]},
    "accel":{"k2_ug_per_g2":[20,0,0],"k3_ug_per_g3":[0,1.5,0]}})";
  std::ofstream(d / "model.json") << R"({"format":"imucal-imu-model/1",
    "gyro":{"scale_nonlinear_ppm":{"x":[0,0,0.25]}},"accel":{"k2_ug_per_g2":[19,0,0]},
    "sigma":{"gyro":{"scale_nonlinear_ppm":{"x":[0,0,0.05]}},"accel":{"k2_ug_per_g2":[2,2,2],"k3_ug_per_g3":[1,1,1]}}})";
  const CliRun r = run("compare " + (d / "model.json").string() + " " + (d / "truth.json").string() + " --json " +
                       (d / "cmp.json").string());
  ASSERT_EQ(r.status, 0) << r.output;
  const auto rows = nlohmann::json::parse(std::ifstream(d / "cmp.json")).at("rows");
  std::map<std::string, nlohmann::json> by_name;
  for (const auto& row : rows) by_name[row.at("name").get<std::string>()] = row;
  EXPECT_NEAR(by_name.at("gyro.scale_nonlinear_ppm.x.c3").at("error").get<double>(), 0.05, 1e-9);
  EXPECT_NEAR(by_name.at("gyro.scale_nonlinear_ppm.x.c3").at("sigma").get<double>(), 0.05, 1e-9);
  EXPECT_NEAR(by_name.at("gyro.g_sensitivity_dph_per_g.x.z").at("truth").get<double>(), 0.004, 1e-12);
  EXPECT_NEAR(by_name.at("accel.k2_ug_per_g2.x").at("error").get<double>(), -1.0, 1e-9);
  EXPECT_NEAR(by_name.at("accel.k3_ug_per_g3.y").at("truth").get<double>(), 1.5, 1e-9);
  EXPECT_TRUE(by_name.count("accel.k3_ug_per_g3.z")) << "its uncertainty is stated";
  EXPECT_FALSE(by_name.count("gyro.scale_nonlinear_ppm.y.c1")) << "neither model has it";
  EXPECT_TRUE(by_name.count("gyro.bias_dph.y")) << "the linear terms always";
  EXPECT_NE(r.output.find("gyro.g_sensitivity_dph_per_g.x.z"), std::string::npos) << r.output;
}

TEST(Cli, SimulateCalibrateNavigateExportImport) {
  const fs::path d = fresh_dir("cli-e2e");
  const std::string db = (d / "run.db").string();
  CliRun r = run("simulate --program direct-short --imu ideal --db " + db + " --rate 50 --seed 3");
  ASSERT_EQ(r.status, 0) << r.output;
  r = run("calibrate --db " + db + " --stage all --out " + (d / "model.json").string());
  ASSERT_EQ(r.status, 0) << r.output;
  EXPECT_NE(r.output.find("ran stage direct"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("skipped stage lever-arm"), std::string::npos) << r.output;
  const imucal::ImuModel m = imucal::read_imu_model_file((d / "model.json").string());
  ASSERT_TRUE(m.sigma.has_value());
  EXPECT_LT(std::abs(m.gyro.bias_radps[0]), 1e-7);  // ideal IMU: small, not NaN
  // compare keeps a small value's digits (an ideal IMU's accelerometer bias is ~1e-11 m/s^2).
  r = run("compare " + (d / "model.json").string() + " " + (d / "model.json").string());
  ASSERT_EQ(r.status, 0) << r.output;
  {
    const auto at = r.output.find("accel.bias_mps2.x");
    ASSERT_NE(at, std::string::npos) << r.output;
    std::istringstream line(r.output.substr(at));
    std::string name;
    double printed = 0;
    line >> name >> printed;
    ASSERT_NE(m.accel.bias_mps2[0], 0.0);
    EXPECT_NEAR(printed / m.accel.bias_mps2[0], 1.0, 1e-6) << r.output;
  }
  r = run("navigate --db " + db + " --model " + (d / "model.json").string() + " --out " + (d / "nav.csv").string() +
          " --summary-json " + (d / "summary.json").string());
  ASSERT_EQ(r.status, 0) << r.output;
  const auto summary = nlohmann::json::parse(std::ifstream(d / "summary.json"));
  for (const char* key : {"duration_s", "max_velocity_error_mps", "max_position_error_m"})
    EXPECT_TRUE(summary.contains(key)) << key;
  EXPECT_GT(summary["duration_s"].get<double>(), 300.0);
  r = run("export --db " + db + " --out " + (d / "bundle").string());
  ASSERT_EQ(r.status, 0) << r.output;
  r = run("import " + (d / "bundle").string() + " --db " + (d / "back.db").string());
  ASSERT_EQ(r.status, 0) << r.output;
  // import(export(run)) reproduces the run exactly.
  const auto a = imucal::storage::RunDb::open(db).read_frames();
  const auto b = imucal::storage::RunDb::open((d / "back.db").string()).read_frames();
  ASSERT_EQ(a.size(), b.size());
  for (std::size_t i = 0; i < a.size(); ++i) {
    ASSERT_EQ(a[i].t_ns, b[i].t_ns);
    ASSERT_TRUE(a[i].dtheta_rad == b[i].dtheta_rad && a[i].dv_mps == b[i].dv_mps && a[i].table_deg == b[i].table_deg)
        << "frame " << i;
  }
}

TEST(Cli, MalformedBundleIsRefusedWithItsLine) {
  const fs::path d = fresh_dir("cli-bad-bundle");
  fs::copy_file(imucaltest::test_data_dir() + "/example-direct/meta.json", d / "meta.json");
  std::ifstream in(imucaltest::test_data_dir() + "/example-direct/frames.csv");
  std::ofstream out(d / "frames.csv");
  std::string line;
  for (int i = 0; i < 10 && std::getline(in, line); ++i) out << (i == 6 ? "0.35,abc" + line.substr(line.find(',', 9)) : line) << "\n";
  out.close();
  const CliRun r = run("import " + d.string() + " --db " + (d / "x.db").string());
  EXPECT_NE(r.status, 0);
  EXPECT_NE(r.output.find("line 7"), std::string::npos) << r.output;
}

namespace {

// The number before " rejected" in the navigation stage's report line.
long rejected_in(const std::string& output) {
  const auto at = output.find(" rejected");
  if (at == std::string::npos) return -1;
  auto start = output.rfind(' ', at - 1);
  return std::stol(output.substr(start + 1, at - start - 1));
}

}  // namespace

TEST(Cli, ThermalSectionIsAppliedByNavigateAndTheNavigationStage) {
  // A simulated half hour across a chamber ramp, navigated and refined (stage 3) with a model that
  // has the truth's thermal section and with the same model without it: both commands must feed
  // the run's temperatures to the compensation.
  const fs::path d = fresh_dir("cli-thermal-nav");
  const std::string db = (d / "run.db").string();
  const std::string truth = imucaltest::source_dir() + "/examples/truth-thermal.json";
  CliRun r = run("simulate --program thermal-short --chamber thermal-short --imu " + truth + " --db " + db +
                 " --rate 20 --duration 1800 --seed 4");
  ASSERT_EQ(r.status, 0) << r.output;
  auto constants_only = nlohmann::json::parse(std::ifstream(truth));
  constants_only.erase("thermal");
  std::ofstream(d / "constants.json") << constants_only.dump(1);

  auto navigate = [&](const std::string& model) {
    const CliRun n = run("navigate --db " + db + " --model " + model + " --out " + (d / "nav.csv").string() +
                         " --summary-json " + (d / "summary.json").string());
    EXPECT_EQ(n.status, 0) << n.output;
    return nlohmann::json::parse(std::ifstream(d / "summary.json"))["max_velocity_error_mps"].get<double>();
  };
  const double v_with = navigate(truth), v_without = navigate((d / "constants.json").string());
  std::printf("navigate: %.3f m/s with the thermal section, %.3f m/s without\n", v_with, v_without);
  EXPECT_LT(v_with, 0.3 * v_without);

  const CliRun with = run("calibrate --db " + db + " --stage navigation --model " + truth + " --out " +
                          (d / "nav-with.json").string());
  ASSERT_EQ(with.status, 0) << with.output;
  const CliRun without = run("calibrate --db " + db + " --stage navigation --model " + (d / "constants.json").string() +
                             " --out " + (d / "nav-without.json").string());
  const long rejected_with = rejected_in(with.output), rejected_without = rejected_in(without.output);
  std::printf("stage navigation: %ld innovations rejected with the thermal section, %ld without (status %d)\n",
              rejected_with, rejected_without, without.status);
  EXPECT_GE(rejected_with, 0) << with.output;
  EXPECT_GT(rejected_without, 10 * rejected_with + 100) << without.output;
}

// simulate --table: the table moves with the certificate's geometry and the run records it;
// calibrate applies the recording's geometry (an error-free IMU then calibrates to zero: the
// ideal table's reference leaves arc seconds in its angles); export writes it into meta.json.
TEST(Cli, SimulateOnAnImperfectTable) {
  const fs::path d = fresh_dir("cli-table");
  const std::string db = (d / "run.db").string();
  // A recording's meta.json names the table too: the independent example's.
  CliRun r = run("simulate --program direct-short --imu ideal --db " + db + " --rate 20 --seed 3 --table " +
                 imucaltest::test_data_dir() + "/example-table/meta.json");
  ASSERT_EQ(r.status, 0) << r.output;
  r = run("calibrate --db " + db + " --stage direct --out " + (d / "model.json").string());
  ASSERT_EQ(r.status, 0) << r.output;
  const imucal::ImuModel m = imucal::read_imu_model_file((d / "model.json").string());
  for (const auto& [name, k] : imucal::kMisalignmentKeys) {
    EXPECT_LT(std::abs(m.gyro.misalignment_rad.*k) * imucal::units::kRadToArcsec, 0.02) << name;
    EXPECT_LT(std::abs(m.accel.misalignment_rad.*k) * imucal::units::kRadToArcsec, 0.02) << name;
  }
  r = run("export --db " + db + " --out " + (d / "bundle").string());
  ASSERT_EQ(r.status, 0) << r.output;
  const auto meta = nlohmann::json::parse(std::ifstream(d / "bundle" / "meta.json"));
  const auto given = nlohmann::json::parse(std::ifstream(imucaltest::test_data_dir() + "/example-table/meta.json"));
  EXPECT_NEAR(meta.at("table").at("geometry").at("middle_axis_arcsec").at(0).get<double>(),
              given.at("table").at("geometry").at("middle_axis_arcsec").at(0).get<double>(), 1e-12);
  EXPECT_EQ(meta.at("table").at("certificate"), given.at("table").at("certificate"));

  // A table file with a wrong value is refused with its path.
  std::ofstream(d / "bad-table.json") << R"({"geometry": {"outer_tilt_arcsec": [1, "2"]}})";
  r = run("simulate --program direct-short --imu ideal --db " + (d / "bad.db").string() + " --table " +
          (d / "bad-table.json").string());
  EXPECT_NE(r.status, 0);
  EXPECT_NE(r.output.find("geometry.outer_tilt_arcsec[1]"), std::string::npos) << r.output;
}

// `imucal plan` on a bench (issue 34): the table's certificate from a recording's meta.json and a
// measured g; each coefficient's dominant source beside its sigma, the bench's requirements for
// stage 1's limits, and the JSON with the same; the two table options exclude each other.
// Stage 3's: PlanBudget.StageThreeStatesItsBenchRequirements (test_plan).
TEST(Cli, PlanNamesTheDominantSourceAndTheTableItNeeds) {
  const fs::path dir = fresh_dir("cli-plan-bench");
  const std::string out = (dir / "plan.json").string();
  const CliRun r = run("plan --program direct-short --rate 20 --imu " + imucaltest::source_dir() +
                       "/examples/truth-nav-grade.json --table " + imucaltest::source_dir() +
                       "/tests/data/example-table/meta.json --gravity-sigma-mps2 1e-6 --json " + out);
  ASSERT_EQ(r.status, 0) << r.output;
  EXPECT_NE(r.output.find("dominant source (its share of u^2)"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("direct: table.middle_axis_arcsec ("), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("the bench for stage 1's limits"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("table.outer_tilt_arcsec            0.2"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("the whole table certificate scaled together"), std::string::npos) << r.output;
  std::ifstream in(out);
  const nlohmann::json j = nlohmann::json::parse(in);
  const nlohmann::json& direct = j.at("stages").at("direct");
  EXPECT_EQ(direct.at("requirements").at("sources").size(), 7u);
  EXPECT_EQ(direct.at("requirements").at("limits").at("gyro.bias_dph"), 0.002);
  EXPECT_TRUE(direct.at("budget").at("gyro.bias_dph.x").contains("dominant"));
  const CliRun both = run("plan --program direct-short --imu " + imucaltest::source_dir() +
                          "/examples/truth-nav-grade.json --table " + imucaltest::source_dir() +
                          "/tests/data/example-table/meta.json --table-sigma-arcsec 1");
  EXPECT_NE(both.status, 0);
  EXPECT_NE(both.output.find("excludes"), std::string::npos) << both.output;
}

// keygen, then a document signed with its key (the daemon signs; the CLI only verifies), checked
// by `imucal verify`: 0 only when every check passes, 1 naming the check that failed, 2 for a
// command line it cannot run (docs/signing.md).
TEST(Cli, KeygenThenVerifyNamesTheFailingCheck) {
  const auto exit_status = [](const CliRun& r) { return WIFEXITED(r.status) ? WEXITSTATUS(r.status) : -1; };
  const fs::path d = fresh_dir("cli-sign");
  const std::string key = (d / "lab.key").string();
  CliRun r = run("keygen --out " + key);
  ASSERT_EQ(exit_status(r), 0) << r.output;
  const auto at = r.output.find("fingerprint: ");
  ASSERT_NE(at, std::string::npos) << r.output;
  const std::string fp = r.output.substr(at + 13, r.output.find('\n', at) - at - 13);
  const imucal::signing::KeyPair lab = imucal::signing::read_key_file(key);
  EXPECT_EQ(fp, imucal::signing::fingerprint(lab.public_key));
  EXPECT_NE(r.output.find("\"certificates\": {\"signing_key_file\": \"" + key + "\"}"), std::string::npos) << r.output;
  r = run("keygen --out " + key);
  EXPECT_EQ(exit_status(r), 1) << r.output;
  EXPECT_NE(r.output.find(key + " already exists"), std::string::npos) << r.output;

  const nlohmann::json content = {{"number", "LAB-2026-000007"},
                                  {"unit", {{"serial", "IMU-0007"}}},
                                  {"results", {{"gyro", {{"bias_dph", {0.0123, -0.0071, 0.0042}}}}}}};
  const std::string good = (d / "certificate.json").string();
  std::ofstream(good) << imucal::signing::sign_document(content, imucal::signing::kCertificate, lab).dump(2);
  r = run("verify " + good + " --key " + key + ".pub");
  EXPECT_EQ(exit_status(r), 0) << r.output;
  for (const char* check : {"format", "content hash", "signature", "key"})
    EXPECT_NE(r.output.find("  " + std::string(check)), std::string::npos) << r.output;
  EXPECT_EQ(r.output.find("FAILED"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("VERIFIED: a certificate signed by the lab's key " + fp), std::string::npos) << r.output;
  r = run("verify " + good + " --fingerprint " + fp);
  EXPECT_EQ(exit_status(r), 0) << r.output;
  // No lab key: intact, but not verified.
  r = run("verify " + good);
  EXPECT_EQ(exit_status(r), 1) << r.output;
  EXPECT_NE(r.output.find("NOT CHECKED"), std::string::npos) << r.output;

  // A digit changed in the file.
  std::stringstream text;
  text << std::ifstream(good).rdbuf();
  std::string tampered_text = text.str();
  tampered_text.replace(tampered_text.find("0.0123"), 6, "0.0124");
  const std::string tampered = (d / "tampered.json").string();
  std::ofstream(tampered) << tampered_text;
  r = run("verify " + tampered + " --key " + key + ".pub");
  EXPECT_EQ(exit_status(r), 1) << r.output;
  EXPECT_NE(r.output.find("NOT VERIFIED: the content hash check failed"), std::string::npos) << r.output;

  // Another lab's key.
  const std::string other = (d / "other.key").string();
  ASSERT_EQ(exit_status(run("keygen --out " + other)), 0);
  r = run("verify " + good + " --key " + other + ".pub");
  EXPECT_EQ(exit_status(r), 1) << r.output;
  EXPECT_NE(r.output.find("NOT VERIFIED: the key check failed"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("not by the lab's key " + imucal::signing::fingerprint(imucal::signing::read_public_key(other))),
            std::string::npos)
      << r.output;

  // Command lines verify cannot run: 2.
  EXPECT_EQ(exit_status(run("verify " + good + " --key " + key + ".pub --fingerprint " + fp)), 2);
  r = run("verify " + good + " --fingerprint ed25519:1234");
  EXPECT_EQ(exit_status(r), 2) << r.output;
  EXPECT_NE(r.output.find("not a key fingerprint"), std::string::npos) << r.output;
  EXPECT_EQ(exit_status(run("verify " + (d / "no-such.json").string())), 2);
  r = run("verify " + good + " --key " + good);
  EXPECT_EQ(exit_status(r), 2) << r.output;
  EXPECT_NE(r.output.find("'format'"), std::string::npos) << r.output;
}
