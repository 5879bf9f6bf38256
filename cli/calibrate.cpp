// imucal calibrate: the calibration pipeline (pipeline/pipeline.hpp) on a stored run, and what each
// stage says.
#include "cli/commands.hpp"

#include <algorithm>
#include <cstdio>
#include <fstream>
#include <limits>
#include <optional>
#include <stdexcept>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "core/expect_value.hpp"
#include "core/imu_model.hpp"
#include "estimators/direct_calibration.hpp"
#include "pipeline/pipeline.hpp"
#include "storage/bundle.hpp"
#include "storage/run_db.hpp"
#include "cli/progress.hpp"

namespace imucal::cli {

namespace {

// What each stage of the pipeline says, on stdout: its notes, then its own figures as its folder
// prints them (pipeline/stages/<stage>/).
void print_outcome(const pipeline::Outcome& o) {
  for (const auto& note : o.notes) std::printf("%s\n", note.c_str());
  if (const auto print = pipeline::names_of(o.stage).print) print(o, stdout);
}

// `--report FILE`: the stage's own report, for the stages that write one.
void write_report(const pipeline::Outcome& o, const std::string& path) {
  const auto report_file = pipeline::names_of(o.stage).report_file;
  if (path.empty() || !report_file) return;
  const std::optional<nlohmann::json> report = report_file(o);
  if (!report) return;
  std::ofstream out(path);
  if (!out) throw std::runtime_error(path + ": cannot write");
  out << report->dump(1) << "\n";
}

}  // namespace

// The calibration pipeline (pipeline/) over a stored run: the stages asked, in order, each from
// the model of the ones before; what they leave (history, curves, reports) stored with the run.
int run_calibrate(const CalibrateArgs& a) {
  auto db = storage::RunDb::open(a.db);
  const ImuModel start = a.model.empty() ? ImuModel{} : read_imu_model_file(a.model);
  const bool all = a.stage == "all";
  std::vector<pipeline::Stage> stages;
  if (all) {
    for (const pipeline::StageDescriptor& n : pipeline::stage_registry()) stages.push_back(n.stage);
  } else {
    // The command line admits only the stages' names and "all" (main.cpp: CLI::IsMember).
    stages.push_back(expect_value(pipeline::stage_named(a.stage), "the stage the command line named"));
  }
  pipeline::Settings settings;
  settings.passes = a.passes;
  settings.statics_per_cycle = a.statics_per_cycle;
  settings.thermal_T_ref_C = a.t_ref_C;
  settings.thermal_range_lo_C = a.range_C.at(0);
  settings.thermal_range_hi_C = a.range_C.at(1);
  settings.thermal_keep_shape = a.keep_shape;
  // Stage 1 never integrates a rotation across a gap; list them so the operator knows why one is left out.
  if (std::find(stages.begin(), stages.end(), pipeline::Stage::Direct) != stages.end())
    for (const auto& g : storage::stored_gaps(db))
      std::fprintf(stderr, "gap in the frames: %.6f s .. %.6f s\n", g.t0_s, g.t1_s);

  const auto t0 = Clock::now();
  pipeline::Pipeline run(db.meta(), stages, !all, start, settings);
  run.advance(pipeline::RunDbSource(db), std::numeric_limits<std::int64_t>::max(), true);
  std::vector<std::string> ran, skipped;
  for (const pipeline::Outcome& o : run.outcomes()) {
    const std::string name = pipeline::names_of(o.stage).name;
    print_outcome(o);
    for (const auto& [key, text] : o.extras) db.set_extra(key, text);
    write_report(o, a.report);
    if (o.status == pipeline::Status::Done) {
      ran.push_back(name + " on " + o.source);
    } else if (all) {
      // With --stage all a stage the recording cannot support is skipped with its reason; asked
      // for alone, the same reason is an error.
      skipped.push_back(name + ": " + o.message);
    } else {
      throw std::runtime_error(o.message);
    }
  }
  const ImuModel& model = run.model();
  // Stage 3 works and reports in the body frame: it sees gyro-to-accelerometer alignment only.
  const ImuModel out = (a.frame == "body" || model.frame == "body") ? direct::to_body_frame(model) : model;
  write_imu_model_file(out, a.out);
  for (const auto& s : ran) std::printf("ran stage %s\n", s.c_str());
  for (const auto& s : skipped) std::printf("skipped stage %s\n", s.c_str());
  std::printf("wrote %s (%s frame) in %.1f s\n", a.out.c_str(), out.frame.c_str(), seconds_since(t0));
  return 0;
}

}  // namespace imucal::cli
