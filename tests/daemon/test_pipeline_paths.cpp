// One calibration pipeline: `imucal calibrate --stage X` (the real binary) and the daemon's
// estimator worker, tailing the same run file in the recorder's uneven commit steps, give the same
// model to the last bit, for stage direct, rate-steps, tumble, lever-arm, navigation (stage 3) and
// thermal on a thermal-short recording. The long recordings (the whole navigation program, the whole
// thermal-short run) are in the `slow` variant.
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "../estimators/test_thermal_fixture.hpp"
#include "core/turn_on.hpp"
#include "daemon/subscribers/estimator_worker.hpp"
#include "motion_programs/program.hpp"
#include "pipeline/pipeline.hpp"
#include "sim/simulator.hpp"
#include "storage/run_db.hpp"
#include "subprocess.hpp"
#include "tests/test_paths.hpp"

using namespace imucal;
using nlohmann::json;
namespace fs = std::filesystem;

namespace {

struct Recording {
  std::string path;
  std::int64_t last_t_ns = 0;
};

// Simulates `program` (or its first `duration_s`) into a run file.
Recording record(const std::string& name, const std::string& program_name, double rate_hz, double duration_s,
                 const ImuModel& truth, const sim::ThermalSource* thermal = nullptr) {
  Recording r;
  const fs::path dir = fs::path(imucaltest::test_tmp_dir()) / "pipeline-paths";
  fs::create_directories(dir);
  r.path = (dir / (name + ".db")).string();
  fs::remove(r.path);
  const motion::Program program = motion::load_program(program_name, motion::TableLimits{});
  sim::SimConfig cfg;
  cfg.rate_hz = rate_hz;
  cfg.seed = 5;
  cfg.duration_s = duration_s;
  cfg.thermal = thermal;
  sim::Simulator s(program, truth, cfg);
  auto db = storage::RunDb::create(r.path, s.meta());
  std::vector<ImuFrame> frames;
  ImuFrame f;
  while (s.next(f)) {
    frames.push_back(f);
    r.last_t_ns = f.t_ns;
    if (frames.size() == 50000) {
      db.append(frames);
      frames.clear();
    }
  }
  db.append(frames);
  db.append_temps(s.take_temps());
  db.close();
  return r;
}

ImuModel nav_grade_truth() { return read_imu_model_file(imucaltest::source_dir() + "/examples/truth-nav-grade.json"); }

// The worker's model: the file committed in uneven steps, then finished.
ImuModel worker_model(const Recording& rec, const std::string& estimator, const ImuModel& start) {
  daemon::EstimatorWorker worker(rec.path, {{estimator}, std::nullopt, start}, std::nullopt, [](auto&&...) {});
  for (std::int64_t t_ns = 0; t_ns < rec.last_t_ns; t_ns += 97'300'000'000) worker.committed(t_ns);
  const auto r = worker.finish(rec.last_t_ns);
  EXPECT_EQ(r.results[estimator]["status"], "done") << r.results.dump().substr(0, 2000);
  EXPECT_TRUE(r.model.has_value());
  return r.model.value_or(ImuModel{});
}

// The command line's model from the same file.
ImuModel cli_model(const Recording& rec, const std::string& stage, const ImuModel& start) {
  const fs::path dir = fs::path(rec.path).parent_path();
  const std::string out = (dir / (stage + "-cli.json")).string();
  std::vector<std::string> argv = {imucaltest::program("imucal"), "calibrate", "--db", rec.path, "--stage", stage, "--out", out};
  if (imu_model_to_json_text(start) != imu_model_to_json_text(ImuModel{})) {
    const std::string start_path = (dir / (stage + "-start.json")).string();
    write_imu_model_file(start, start_path);
    argv.insert(argv.end(), {"--model", start_path});
  }
  daemontest::Child child = daemontest::spawn_child(argv, (dir / (stage + "-cli.log")).string());
  const std::string printed = daemontest::read_stdout_until(child, [](const std::string&) { return false; }, 900);
  EXPECT_EQ(daemontest::wait_exit(child.pid, 60), 0) << printed;
  return read_imu_model_file(out);
}

void expect_same_model(const Recording& rec, const std::string& stage, const std::string& estimator,
                       const ImuModel& start = {}) {
  // The command line's model comes through its file, whose units (deg/h, ppm) do not convert back
  // to the last bit: the worker's goes through the same text.
  const std::string online = imu_model_to_json_text(
      imu_model_from_json_text(imu_model_to_json_text(worker_model(rec, estimator, start)), "the worker's model"));
  const std::string offline = imu_model_to_json_text(cli_model(rec, stage, start));
  EXPECT_EQ(online, offline) << "stage " << stage << ": the daemon's worker and imucal calibrate differ";
  // And the stage did something: the model is not the start model.
  EXPECT_NE(online, imu_model_to_json_text(start));
}

}  // namespace

TEST(PipelinePaths, DirectGivesTheSameModelOnlineAndOffline) {
  const Recording rec = record("direct", "direct-short", 50, 0, nav_grade_truth());
  expect_same_model(rec, "direct", "direct");
}

TEST(PipelinePaths, RateStepsGivesTheSameModelOnlineAndOffline) {
  ImuModel truth = nav_grade_truth();
  truth.gyro.scale_nonlinear.row(0) = Eigen::RowVector3d(2.0, 1.0, 0.0) * 1e-6;  // 15 ppm at 300 deg/s
  const Recording rec = record("rate-steps", "rate-steps-short", 50, 0, truth);
  ImuModel stage1 = truth;  // the misalignments a stage-1 model gives; nothing of the scales
  stage1.gyro.scale_pos.setZero();
  stage1.gyro.scale_neg.setZero();
  stage1.gyro.scale_nonlinear.setZero();
  expect_same_model(rec, "rate-steps", "rate-steps", stage1);
  // And the worker's model holds the gyro x nonlinearity within 3 sigma.
  const ImuModel m = worker_model(rec, "rate-steps", stage1);
  ASSERT_TRUE(m.sigma.has_value());
  for (int k = 0; k < 2; ++k) {
    EXPECT_GT(m.sigma->gyro.scale_nonlinear(0, k), 0.0) << "c" << k + 1;
    EXPECT_NEAR(m.gyro.scale_nonlinear(0, k), truth.gyro.scale_nonlinear(0, k), 3.0 * m.sigma->gyro.scale_nonlinear(0, k))
        << "c" << k + 1;
  }
}

TEST(PipelinePaths, TumbleGivesTheSameModelOnlineAndOffline) {
  ImuModel truth = nav_grade_truth();
  truth.accel.k2_per_g = Eigen::Vector3d(30, -45, 22) * 1e-6;
  const Recording rec = record("tumble", "tumble-short", 50, 0, truth);
  ImuModel stage1 = truth;  // the gyro scale factors and angles a stage-1 model gives; no K2
  stage1.accel.k2_per_g.setZero();
  expect_same_model(rec, "tumble", "tumble", stage1);
  const ImuModel m = worker_model(rec, "tumble", stage1);
  ASSERT_TRUE(m.sigma.has_value());
  for (int j = 0; j < 3; ++j)
    EXPECT_NEAR(m.accel.k2_per_g[j], truth.accel.k2_per_g[j], 3.0 * m.sigma->accel.k2_per_g[j]) << "K2 of accelerometer " << j;
}

TEST(PipelinePaths, WarmUpGivesTheSameModelOnlineAndOffline) {
  ImuModel truth = nav_grade_truth();
  TurnOnSection s;
  s.value.gyro_warm_up_radps = Eigen::Vector3d(0.05, -0.03, 0.06) * units::kDphToRadps;
  s.value.gyro_time_constant_s = Eigen::Vector3d(300, 400, 480);
  set_turn_on(truth, s);
  const Recording rec = record("warm-up", "warm-up-short", 20, 0, truth);
  expect_same_model(rec, "warm-up", "warm-up", nav_grade_truth());
  const auto found = turn_on_of(worker_model(rec, "warm-up", nav_grade_truth()));
  ASSERT_TRUE(found.has_value());
  const auto& found_sigma = found->sigma;
  ASSERT_TRUE(found_sigma.has_value());
  for (int j = 0; j < 3; ++j)
    EXPECT_NEAR(found->value.gyro_time_constant_s[j], s.value.gyro_time_constant_s[j], 3.0 * found_sigma->gyro_time_constant_s[j])
        << "the time constant of gyro " << j;
}

TEST(PipelinePaths, LeverArmGivesTheSameModelOnlineAndOffline) {
  const Recording rec = record("lever-arm", "lever-arm", 200, 0, nav_grade_truth());
  ImuModel stage1 = nav_grade_truth();  // lever arms from a known stage-1 model: the truth's constants
  stage1.accel.lever_arm_y_m.setZero();
  stage1.accel.lever_arm_z_m.setZero();
  expect_same_model(rec, "lever-arm", "lever-arm", stage1);
}

TEST(PipelinePaths, NavigationGivesTheSameModelOnlineAndOffline) {
  // The first 25 minutes: the start, the first slow swing and part of the second.
  const Recording rec = record("navigation", "navigation", 50, 1500, nav_grade_truth());
  expect_same_model(rec, "navigation", "stage3", nav_grade_truth());
}

TEST(PipelinePaths, ThermalGivesTheSameModelOnlineAndOffline) {
  // Ninety minutes of the thermal-short chamber run at 20 Hz (10 cycles).
  const thermaltest::ChamberStretch stretch(5400);
  const Recording rec = record("thermal-short", "thermal-short", 20, 5400, stretch.truth, stretch.cfg.thermal);
  expect_same_model(rec, "thermal", "thermal", thermaltest::stage1_of(stretch.truth));
}

// Stage 3 as it runs (what the live page shows): every calibration state's estimate and sigma,
// the delays and proof masses among them, the filter's status, its restarts between the program's
// parts, and the last update's innovations each with its gate.
TEST(PipelinePaths, StageThreeShowsItsFilterWhileItRuns) {
  // 70 minutes at 20 Hz: the slow swings and the restart at the settle before the second set.
  const Recording rec = record("navigation-progress", "navigation", 20, 4200, nav_grade_truth());
  const storage::RunDb db = storage::RunDb::open(rec.path, storage::OpenMode::Read);
  const pipeline::RunDbSource source(db);
  pipeline::Pipeline p(db.meta(), {pipeline::Stage::Navigation}, true, nav_grade_truth());
  const std::int64_t half_ns = rec.last_t_ns / 2;
  ASSERT_FALSE(p.advance(source, half_ns, false));
  const json mid = p.progress(pipeline::Stage::Navigation);
  EXPECT_EQ(mid.at("status"), "running") << mid.dump().substr(0, 500);
  EXPECT_EQ(mid.at("filter_status"), "running");
  EXPECT_GT(mid.at("updates").get<int>(), 100);
  const json& est = mid.at("estimates");
  for (const char* name : {"gyro.bias_dph.x", "accel.misalignment_arcsec.zy", "gyro.delay_us.y", "accel.delay_us.z",
                           "accel.lever_arm_mm.y.x", "accel.lever_arm_mm.z.z"}) {
    ASSERT_TRUE(est.contains(name)) << name << " in " << est.dump().substr(0, 800);
    EXPECT_GT(est.at(name).at(1).get<double>(), 0.0) << name << ": no sigma";
  }
  // The gyro delays are not known at the start (20 us); half-way the sigma has come down.
  EXPECT_LT(est.at("gyro.delay_us.x").at(1).get<double>(), 20.0);
  const json& inn = mid.at("innovations").at("values");
  EXPECT_EQ(inn.size(), 9u) << inn.dump();
  for (const auto& [name, pair] : inn.items()) {
    EXPECT_GT(pair.at(1).get<double>(), 0.0) << name;                                        // a gate
    EXPECT_LE(std::abs(pair.at(0).get<double>()), pair.at(1).get<double>()) << name;          // inside it
  }
  EXPECT_LE(mid.at("innovations").at("t_s").get<double>(), static_cast<double>(half_ns) * 1e-9);

  // Near the end: the navigation has restarted at the start of a later part (a long static).
  ASSERT_FALSE(p.advance(source, rec.last_t_ns - 10'000'000'000, false));
  const json late = p.progress(pipeline::Stage::Navigation);
  std::printf("restarts: %s\n", late.at("restart_times_s").dump().c_str());
  EXPECT_GE(late.at("restarts").get<int>(), 1);
  EXPECT_EQ(late.at("restart_times_s").size(), late.at("restarts").get<std::size_t>());

  ASSERT_TRUE(p.advance(source, rec.last_t_ns, true));
  const json end = p.progress(pipeline::Stage::Navigation);
  EXPECT_EQ(end.at("status"), "done");
  EXPECT_TRUE(end.at("estimates").contains("gyro.delay_us.z"));
  // Finished, it still says what its filter did (the live page ended on a third of the updates
  // and no restarts: issue 36, item 4): its counts at the end, never fewer than before.
  ASSERT_TRUE(end.contains("updates")) << end.dump().substr(0, 500);
  EXPECT_GE(end.at("updates").get<int>(), late.at("updates").get<int>());
  EXPECT_EQ(end.at("restarts"), late.at("restarts"));
  EXPECT_EQ(end.at("restart_times_s"), late.at("restart_times_s"));
  EXPECT_TRUE(end.contains("innovations")) << "the last update's innovations, as the filter ended";
}

// What fed a stage names each program once with its count (issue 36, item 7): a thermal run's
// stage 1 came from some 30 parts of 'direct' between the chamber's steps, once listed 30 times.
TEST(PipelinePaths, AStagesSourceNamesEachProgramOnceWithItsCount) {
  RecordingMeta meta;
  for (int i = 0; i < 30; ++i) {
    meta.segments.push_back({"direct/pos-" + std::to_string(i), "static", 100.0 * i, 100.0 * i + 60.0});
    meta.segments.push_back({"soak/step-" + std::to_string(i), "hold", 100.0 * i + 60.0, 100.0 * i + 100.0});
  }
  const pipeline::Feed thirty = pipeline::feed(pipeline::Stage::Direct, meta, false);
  EXPECT_EQ(thirty.source.rfind("30 parts of 'direct' (", 0), 0u) << thirty.source;
  EXPECT_EQ(thirty.segments.size(), 30u);
  // Two programs, one of them twice; and one part each, named as before.
  meta.segments = {{"direct/a", "static", 0, 10}, {"soak/b", "hold", 10, 20}, {"direct-short/c", "static", 20, 30},
                   {"soak/d", "hold", 30, 40}, {"direct/e", "static", 40, 50}};
  const std::string mixed = pipeline::feed(pipeline::Stage::Direct, meta, false).source;
  EXPECT_EQ(mixed.rfind("2 parts of 'direct', part 'direct-short' (", 0), 0u) << mixed;
  meta.segments.pop_back();
  const std::string each = pipeline::feed(pipeline::Stage::Direct, meta, false).source;
  EXPECT_EQ(each.rfind("parts 'direct', 'direct-short' (", 0), 0u) << each;
  meta.segments.resize(2);  // a part of 'direct' and one of another program
  const std::string one = pipeline::feed(pipeline::Stage::Direct, meta, false).source;
  EXPECT_EQ(one.rfind("part 'direct' (", 0), 0u) << one;
}
