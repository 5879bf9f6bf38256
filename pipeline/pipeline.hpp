// The calibration pipeline: the one place that decides which stages run, in which order, on which
// part of a recording, from which model each starts, when one is skipped and why, and what each
// reports. `imucal calibrate`, the daemon's estimator worker and its analyses all run it, so the
// same recording gives the same model whichever of them asks. The estimators stay pure (frames in,
// results out); the pipeline sequences them over a frame source and never reads a clock.
//
// Parts: a campaign of several programs run in a row names its segments "PROGRAM/segment"
// (imucald joins them so); each program is a part. A recording whose segment names do not all
// carry such a prefix is one part, named by its program (RecordingMeta::program_json).
// Which part feeds which stage: the parts of the built-in program made for that stage (direct and
// direct-short: stage direct; rate-steps and rate-steps-short; tumble and tumble-short;
// lever-arm; thermal and thermal-short; navigation; noise; warm-up and warm-up-short;
// repeatability and repeatability-short). A part of
// an unknown program feeds every stage whose segment requirement it meets. A stage asked for by
// name (`imucal calibrate --stage X`, a campaign's estimator) that no part feeds takes the whole
// recording, as the estimator alone would; with `--stage all` it is skipped with the reason.
#pragma once

#include <any>
#include <array>
#include <cstdio>
#include <deque>
#include <cstdint>
#include <functional>
#include <limits>
#include <memory>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include <nlohmann/json.hpp>

#include "core/imu_model.hpp"
#include "core/recording.hpp"
#include "estimators/direct_calibration.hpp"
#include "estimators/evaluate.hpp"
#include "estimators/lever_arm.hpp"
#include "estimators/nav_filter.hpp"
#include "estimators/noise.hpp"
#include "estimators/rate_steps.hpp"
#include "estimators/repeatability.hpp"
#include "estimators/thermal.hpp"
#include "estimators/tumble.hpp"
#include "estimators/warm_up.hpp"

namespace imucal::storage {
class RunDb;
}

namespace imucal::pipeline {

// A stage's id: its row in the registry (stage_registry(), pipeline/stages/registry.cpp). The named
// values are the built-in stages, for code that names one; a stage registered later
// (register_stage) takes the next id, so the enum holds ids beyond its names.
enum class Stage : int { Direct, RateSteps, Tumble, LeverArm, Thermal, Navigation, Noise, WarmUp, Repeatability };

struct StageDescriptor;  // below, after what a stage is given and leaves
const StageDescriptor& names_of(Stage stage);
std::optional<Stage> stage_named(std::string_view name);
std::optional<Stage> stage_of_estimator(std::string_view estimator);

// The stage a built-in program was made for, or nothing (evaluate, an inline program).
std::optional<Stage> purpose_of_program(std::string_view program);

struct Part {
  std::string program;  // "" when the recording names none
  std::vector<SegmentInfo> segments;
  double t0_s = 0, t1_s = 0;
};
std::vector<Part> parts(const RecordingMeta& meta);

struct Settings {
  direct::Options direct;                // stage direct (its budget's site-g sigma, ...)
  int passes = 1;                        // stage navigation: passes, each starting from the last model
  navfilter::Options navigation;
  int statics_per_cycle = 0;             // stage thermal: for statics without "cycle-NNN/" names
  double thermal_T_ref_C = std::numeric_limits<double>::quiet_NaN();
  double thermal_range_lo_C = 15.0, thermal_range_hi_C = 35.0;
  bool thermal_keep_shape = false;       // fit only the constants, keep the model's polynomials
};

// Why these segments cannot feed the stage (naming the program that would), or nothing.
std::optional<std::string> requirement_unmet(Stage stage, const std::vector<SegmentInfo>& segments,
                                             const Settings& settings = {});

// What feeds a stage: its segments and the frames' time window, or why nothing does.
struct Feed {
  std::vector<SegmentInfo> segments;
  std::int64_t t0_ns = std::numeric_limits<std::int64_t>::min(), t1_ns = std::numeric_limits<std::int64_t>::max();
  std::string source;   // "part 'direct' (t=0..2330 s)", "the whole recording"
  std::string skipped;  // set when nothing feeds it
};
// `asked`: the stage was named (a part-less stage then takes the whole recording).
Feed feed(Stage stage, const RecordingMeta& meta, bool asked, const Settings& settings = {});

// The stages the recording's parts were made for, in pipeline order (a campaign's default
// estimators: {"program": "navigation"} runs stage 3).
std::vector<Stage> stages_for_parts(const RecordingMeta& meta);

// Frames and temperatures of a recording, by time range (both ends included, time order).
class FrameSource {
 public:
  virtual ~FrameSource() = default;
  virtual void frames(std::int64_t t0_ns, std::int64_t t1_ns, const std::function<void(const ImuFrame&)>& fn) const = 0;
  virtual std::vector<TempSample> temps(std::int64_t t0_ns, std::int64_t t1_ns) const = 0;
};

class RunDbSource final : public FrameSource {
 public:
  explicit RunDbSource(const storage::RunDb& db) : db_(db) {}
  void frames(std::int64_t t0_ns, std::int64_t t1_ns, const std::function<void(const ImuFrame&)>& fn) const override;
  std::vector<TempSample> temps(std::int64_t t0_ns, std::int64_t t1_ns) const override;

 private:
  const storage::RunDb& db_;
};

// A recording held in memory (frames in time order): a simulation fed straight to the pipeline.
class MemorySource final : public FrameSource {
 public:
  MemorySource(std::vector<ImuFrame> frames, std::vector<TempSample> temps = {})
      : frames_(std::move(frames)), temps_(std::move(temps)) {}
  void frames(std::int64_t t0_ns, std::int64_t t1_ns, const std::function<void(const ImuFrame&)>& fn) const override;
  std::vector<TempSample> temps(std::int64_t t0_ns, std::int64_t t1_ns) const override;

 private:
  std::vector<ImuFrame> frames_;
  std::vector<TempSample> temps_;
};

// Feeds the frames of a window of a source in steps, as they become available, each temperature
// before the frames after it (all temperatures from the recording's start: a compensation's
// rate looks back). Fed in any number of steps, a consumer sees the same sequence.
class Feeder {
 public:
  Feeder(std::int64_t t0_ns = std::numeric_limits<std::int64_t>::min(),
         std::int64_t t1_ns = std::numeric_limits<std::int64_t>::max())
      : t0_ns_(t0_ns), t1_ns_(t1_ns) {}
  void feed(const FrameSource& source, std::int64_t available_t_ns, const std::function<void(const TempSample&)>& temp,
            const std::function<void(const ImuFrame&)>& frame);
  // Every frame of the window is available.
  bool complete(std::int64_t available_t_ns) const { return available_t_ns >= t1_ns_; }
  void rewind();  // from the window's start again
  std::optional<std::int64_t> fed_t_ns() const { return fed_t_ns_; }

 private:
  std::int64_t t0_ns_, t1_ns_;
  std::optional<std::int64_t> fed_t_ns_;   // the last frame fed
  std::vector<TempSample> pending_temps_;  // read, not yet pushed (after the last frame fed)
  std::optional<std::int64_t> temps_read_to_ns_;
};

// The Schuler test of a model on a recording of the evaluate program (its tilt and coning
// segments), compensated at the run's temperatures when the model has a thermal section.
evaluate::Result evaluate_recording(const RecordingMeta& meta, const FrameSource& source, const ImuModel& model);

// Flat "gyro.bias_dph.x" -> [estimate, sigma] of a model, in the units the names carry (live
// progress, reports).
nlohmann::json estimates_json(const ImuModel& model);

// Undetermined: the recording cannot determine some coefficient (the message names it).
enum class Status { Pending, Running, Done, Skipped, Undetermined, Failed };
const char* to_string(Status status);

// One stage's outcome: its model (the input's other coefficients carried over), its estimator's
// own result for the shells to print, the run extras it leaves (history, curves, report) and its
// report for the daemon's results.
struct Outcome {
  Stage stage = Stage::Direct;
  Status status = Status::Pending;
  std::string source;   // what fed it
  std::string message;  // skipped or failed: why
  std::vector<std::string> notes;
  std::optional<ImuModel> model;  // Done (and a navigation pass that did not converge: its estimates)
  // The stage's estimator's own result (direct::Result, thermal::Result, ...), when it gave one:
  // one slot whatever the stage, so that a new stage adds no field here. Read it with result_as.
  std::any result;
  template <class Result>
  const Result* result_as() const {
    return std::any_cast<Result>(&result);
  }
  std::vector<std::pair<std::string, std::string>> extras;  // run extras: key, JSON text
  std::int64_t frames = 0;
  double program_time_s = 0;  // of the last frame fed
  // The stage's own progress figures as its run ended (stage 3's updates, rejections, restarts and
  // last innovations): a finished stage still reports them, not only its estimates.
  nlohmann::json last_progress;
  // {"status", "source", "notes", per-stage figures, "model"} (docs/api.md, results).
  nlohmann::json report() const;
};

// What a stage's runner is given when its window opens: the recording, what feeds it, the model it
// starts from and the pipeline's settings (all outlive the runner).
struct StageContext {
  const RecordingMeta& meta;
  const Feed& feed;
  const ImuModel& start;
  const Settings& settings;
};
class StageRun;  // pipeline/stage.hpp

// A stage as one unit (pipeline/stages/<stage>/): its names, what it needs, its runner, its report
// and its printer. The built-in stages are one table in pipeline order (pipeline/stages/registry.cpp).
struct StageDescriptor {
  Stage stage;
  const char* name;           // `imucal calibrate --stage NAME`, reports
  const char* estimator;      // the campaign's estimator that runs it online in imucald
  const char* program;        // the built-in program made for it (docs/programs.md)
  const char* short_program;  // its short form, or nullptr
  // May start from a body-frame model: the stage needs no instrument-frame axes (stage 3 works in
  // the body frame; noise, warm-up and repeatability only carry the model over).
  bool any_frame_start;
  // Why these segments cannot feed the stage (naming the program that would), or nothing.
  std::optional<std::string> (*requirement)(const std::vector<SegmentInfo>& segments, const Settings& settings);
  std::unique_ptr<StageRun> (*make_run)(const StageContext& context);
  // Adds the stage's own figures to its outcome's report (when it has its result).
  void (*report)(const Outcome& outcome, nlohmann::json& report);
  // `imucal calibrate`'s lines for the stage's own figures (after its notes).
  void (*print)(const Outcome& outcome, std::FILE* out);
  // What `imucal calibrate --report FILE` writes for it (nothing without its result); nullptr: none.
  std::optional<nlohmann::json> (*report_file)(const Outcome& outcome);
};
// Every stage, in pipeline order: each starts from the model of the stages before it. A deque:
// a registration keeps the references names_of() gave out.
const std::deque<StageDescriptor>& stage_registry();
// Adds a stage after the built-in ones (a test's stage); returns its id (`descriptor.stage` is
// ignored). Register before any pipeline runs: the registry is not guarded against threads.
Stage register_stage(StageDescriptor descriptor);

// What a calibration leaves the daemon: each stage's report under its estimator's name, and the
// model of the last stage done (none when no stage was). One rule for a run's online estimators
// and for a run calibrated again from its recording.
struct Calibration {
  nlohmann::json reports = nlohmann::json::object();
  std::optional<ImuModel> model;
};
Calibration calibration_of(const std::vector<Outcome>& outcomes);

class Pipeline {
 public:
  // `stages`: in any order (run in pipeline order); `asked` as for feed(). `start`: the model the
  // first stage starts from (ideal by default); a body-frame start model is refused unless the only
  // stages are navigation (stage 3 works in the body frame), noise, warm-up and repeatability.
  Pipeline(const RecordingMeta& meta, std::vector<Stage> stages, bool asked, ImuModel start = {},
           Settings settings = {});
  ~Pipeline();
  Pipeline(const Pipeline&) = delete;
  Pipeline& operator=(const Pipeline&) = delete;

  // Feeds the stages every frame of `source` up to `available_t_ns` they have not seen, finishing
  // each whose window is complete (`final`: the recording ends here). The same calls in any
  // number of steps give the same results. Returns true when every stage has finished.
  bool advance(const FrameSource& source, std::int64_t available_t_ns, bool final);
  bool finished() const;

  const std::vector<Outcome>& outcomes() const { return outcomes_; }
  // The model after the last stage that finished (the start model before any).
  const ImuModel& model() const { return model_; }
  // The live progress of stage `stage` ({"status", "program_time_s", ...}, docs/api.md); a finished
  // stage keeps its run's last figures (stage 3's counts) beside its outcome.
  nlohmann::json progress(Stage stage) const;

 private:
  RecordingMeta meta_;
  Settings settings_;
  std::vector<Feed> feeds_;
  std::vector<Outcome> outcomes_;
  ImuModel model_;
  std::size_t active_ = 0;
  std::unique_ptr<StageRun> run_;  // the active stage over its window
  Feeder feeder_;

  void keep_last_progress(Outcome& out) const;
};

// Convenience for a stored recording read to its end (the command line, the analyses).
std::vector<Outcome> run_to_end(const storage::RunDb& db, std::vector<Stage> stages, bool asked, const ImuModel& start,
                                const Settings& settings = {});
// The same through any frame source (e.g. one that reports how far the reading has come).
std::vector<Outcome> run_to_end(const RecordingMeta& meta, const FrameSource& source, std::vector<Stage> stages,
                                bool asked, const ImuModel& start, const Settings& settings = {});

// A frame source that passes another's frames on and reports the share of the recording read so
// far (by the frames' program time against `end_s`, mapped onto [from, from + span]) every 65 536
// frames: the daemon's analyses show it as their progress.
class ProgressSource final : public FrameSource {
 public:
  ProgressSource(const FrameSource& inner, double end_s, std::function<void(double)> report, double from = 0.0,
                 double span = 1.0)
      : inner_(inner), end_s_(end_s), report_(std::move(report)), from_(from), span_(span) {}
  void frames(std::int64_t t0_ns, std::int64_t t1_ns, const std::function<void(const ImuFrame&)>& fn) const override;
  std::vector<TempSample> temps(std::int64_t t0_ns, std::int64_t t1_ns) const override { return inner_.temps(t0_ns, t1_ns); }

 private:
  const FrameSource& inner_;
  double end_s_;
  std::function<void(double)> report_;
  double from_, span_;
};
// The program time at which a recording ends (its last segment's end; 0 without segments).
double end_of_program_s(const RecordingMeta& meta);

}  // namespace imucal::pipeline
