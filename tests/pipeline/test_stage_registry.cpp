// The stage registry is open: a stage defined by the test suite (tests/pipeline/mean_force/, one
// folder) and registered by one line runs through the Pipeline on a small simulated recording like
// any built-in stage, its report appears under its name, and the built-in stages keep their order.
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <functional>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

#include <gtest/gtest.h>

#include "core/units.hpp"
#include "motion_programs/program.hpp"
#include "pipeline/pipeline.hpp"
#include "sim/simulator.hpp"
#include "tests/pipeline/mean_force/mean_force_stage.hpp"

using namespace imucal;
using nlohmann::json;

namespace {

namespace mf = imucaltest::mean_force_stage;

// The one line that adds the stage (a built-in stage's line is in pipeline/stages/registry.cpp).
const pipeline::Stage kMeanForce = pipeline::register_stage(
    {{}, "mean-force", "mean-force", "mean-force", nullptr, true, mf::requirement, mf::make_run, mf::report, mf::print, nullptr});


// The first 30 s of the noise program (the table holds still) at 100 Hz from an ideal IMU.
struct Simulated {
  RecordingMeta meta;
  std::vector<ImuFrame> frames;
  std::vector<TempSample> temps;
};
Simulated simulate_still() {
  const motion::Program program = motion::load_program("noise", motion::TableLimits{});
  sim::SimConfig cfg;
  cfg.rate_hz = 100;
  cfg.seed = 3;
  cfg.duration_s = 30;
  sim::Simulator s(program, ImuModel{}, cfg);
  Simulated out;
  out.meta = s.meta();
  ImuFrame f;
  while (s.next(f)) out.frames.push_back(f);
  out.temps = s.take_temps();
  return out;
}

}  // namespace

TEST(StageRegistry, BuiltInStagesKeepTheirOrderAndTheTestStageComesAfter) {
  const auto& stages = pipeline::stage_registry();
  ASSERT_EQ(stages.size(), 10u);
  const std::vector<std::string> expected = {"direct",     "rate-steps", "tumble",  "lever-arm",     "thermal",
                                             "navigation", "noise",      "warm-up", "repeatability", "mean-force"};
  for (std::size_t i = 0; i < stages.size(); ++i) {
    EXPECT_EQ(stages[i].name, expected[i]);
    EXPECT_EQ(static_cast<std::size_t>(stages[i].stage), i);  // a row's index is its id
  }
  EXPECT_EQ(pipeline::stage_named("mean-force"), kMeanForce);
  EXPECT_EQ(pipeline::stage_of_estimator("stage3"), pipeline::Stage::Navigation);
  EXPECT_THROW(pipeline::register_stage(stages.back()), std::invalid_argument);  // one name, one stage
}

TEST(StageRegistry, ATestStageRunsThroughThePipelineAndReportsUnderItsName) {
  const Simulated rec = simulate_still();
  const pipeline::MemorySource source(rec.frames, rec.temps);
  pipeline::Pipeline p(rec.meta, {kMeanForce}, true);
  EXPECT_TRUE(p.advance(source, rec.frames.back().t_ns, true));
  ASSERT_EQ(p.outcomes().size(), 1u);
  const pipeline::Outcome& o = p.outcomes().front();
  ASSERT_EQ(o.status, pipeline::Status::Done) << o.message;
  EXPECT_EQ(o.frames, static_cast<std::int64_t>(rec.frames.size()));

  const pipeline::Calibration c = pipeline::calibration_of(p.outcomes());
  ASSERT_TRUE(c.reports.contains("mean-force")) << c.reports.dump();
  const json& report = c.reports.at("mean-force");
  EXPECT_EQ(report.at("stage"), "mean-force");
  EXPECT_EQ(report.at("status"), "done");
  const json& f = report.at("mean_specific_force_mps2");
  ASSERT_EQ(f.size(), 3u);
  // Still on the table: the specific force is gravity's reaction, whatever the IMU's attitude.
  const double norm_mps2 = std::hypot(f[0].get<double>(), f[1].get<double>(), f[2].get<double>());
  EXPECT_NEAR(norm_mps2, units::kStandardGravity_mps2, 0.05);

  // Its printer, through the registry as `imucal calibrate` prints.
  std::FILE* out = std::tmpfile();
  ASSERT_NE(out, nullptr);
  pipeline::names_of(o.stage).print(o, out);
  std::rewind(out);
  char line[160] = {};
  ASSERT_NE(std::fgets(line, sizeof line, out), nullptr);
  std::fclose(out);
  EXPECT_EQ(std::string(line).rfind("mean specific force ", 0), 0u) << line;
}

TEST(StageRegistry, ATestStageTheRecordingCannotFeedIsSkippedWithItsReason) {
  RecordingMeta meta;
  meta.segments = {{"swing", "sine", 0.0, 10.0}};
  const pipeline::MemorySource source({}, {});
  pipeline::Pipeline p(meta, {kMeanForce}, false);
  p.advance(source, 0, true);
  EXPECT_EQ(p.outcomes().front().status, pipeline::Status::Skipped);
  EXPECT_EQ(p.outcomes().front().message, "stage mean-force needs a static segment; there is none");
}
