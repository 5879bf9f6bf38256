#include "pipeline/pipeline.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <set>
#include <stdexcept>

#include "core/coefficients.hpp"
#include "core/units.hpp"
#include "storage/run_db.hpp"

namespace imucal::pipeline {

using nlohmann::json;

namespace {

constexpr std::int64_t kMinNs = std::numeric_limits<std::int64_t>::min();
constexpr std::int64_t kMaxNs = std::numeric_limits<std::int64_t>::max();
// A part's window opens this much before its first segment: stage 1 needs the frame before its
// first static, the filters a start on the frame grid.
constexpr double kLead_s = 1.0;

double seconds(std::int64_t t_ns) { return static_cast<double>(t_ns) / units::kNsPerS; }
std::int64_t nanoseconds(double t_s) { return std::llround(t_s * units::kNsPerS); }

bool is_static(const SegmentInfo& s) { return s.kind == "static" || s.kind == "tilt"; }
int count_kind(const std::vector<SegmentInfo>& segments, const char* kind) {
  return static_cast<int>(std::count_if(segments.begin(), segments.end(), [&](const SegmentInfo& s) { return s.kind == kind; }));
}

// A joined campaign prefixes every segment with its program's name and a '/'.
std::string part_prefix(const std::string& name) {
  const auto slash = name.find('/');
  return slash == std::string::npos ? std::string() : name.substr(0, slash);
}

std::string program_name(const RecordingMeta& meta) {
  if (meta.program_json.empty()) return {};
  try {
    const json p = json::parse(meta.program_json);
    if (p.is_object() && p.contains("name") && p.at("name").is_string()) return p.at("name").get<std::string>();
  } catch (const json::exception&) {
  }
  return {};
}

// The thermal stage's cycles within a part: "thermal/cycle-001/z-up" is "cycle-001/z-up" there.
std::vector<SegmentInfo> without_part_prefix(std::vector<SegmentInfo> segments) {
  for (SegmentInfo& s : segments)
    if (const auto p = s.name.find("/cycle-"); p != std::string::npos) s.name = s.name.substr(p + 1);
  return segments;
}

std::vector<thermal::Cycle> cycles_of(const std::vector<SegmentInfo>& segments, const Settings& settings) {
  try {
    return thermal::find_cycles(without_part_prefix(segments), settings.statics_per_cycle);
  } catch (const std::exception&) {
    return {};
  }
}

std::string span_text(double t0_s, double t1_s) {
  char buf[64];
  std::snprintf(buf, sizeof buf, "t=%.0f..%.0f s", t0_s, t1_s);
  return buf;
}

}  // namespace

// ------------------------------------------------------------------------------------------------
const std::array<StageName, 9>& stage_names() {
  static const std::array<StageName, 9> names = {{{Stage::Direct, "direct", "direct", "direct"},
                                                  {Stage::RateSteps, "rate-steps", "rate-steps", "rate-steps"},
                                                  {Stage::Tumble, "tumble", "tumble", "tumble"},
                                                  {Stage::LeverArm, "lever-arm", "lever-arm", "lever-arm"},
                                                  {Stage::Thermal, "thermal", "thermal", "thermal"},
                                                  {Stage::Navigation, "navigation", "stage3", "navigation"},
                                                  {Stage::Noise, "noise", "noise", "noise"},
                                                  {Stage::WarmUp, "warm-up", "warm-up", "warm-up"},
                                                  {Stage::Repeatability, "repeatability", "repeatability", "repeatability"}}};
  return names;
}

const StageName& names_of(Stage stage) {
  for (const StageName& n : stage_names())
    if (n.stage == stage) return n;
  throw std::logic_error("pipeline: a stage without a name");
}

std::optional<Stage> stage_named(std::string_view name) {
  for (const StageName& n : stage_names())
    if (name == n.name) return n.stage;
  return std::nullopt;
}

std::optional<Stage> stage_of_estimator(std::string_view estimator) {
  for (const StageName& n : stage_names())
    if (estimator == n.estimator) return n.stage;
  return std::nullopt;
}

std::optional<Stage> purpose_of_program(std::string_view program) {
  if (program == "direct-short") return Stage::Direct;
  if (program == "thermal-short") return Stage::Thermal;
  if (program == "rate-steps-short") return Stage::RateSteps;
  if (program == "tumble-short") return Stage::Tumble;
  if (program == "warm-up-short") return Stage::WarmUp;
  if (program == "repeatability-short") return Stage::Repeatability;
  for (const StageName& n : stage_names())
    if (program == n.program) return n.stage;
  return std::nullopt;
}

std::vector<Part> parts(const RecordingMeta& meta) {
  std::vector<SegmentInfo> segments = meta.segments;
  std::sort(segments.begin(), segments.end(), [](const SegmentInfo& a, const SegmentInfo& b) { return a.t0_s < b.t0_s; });
  const bool joined = !segments.empty() && std::all_of(segments.begin(), segments.end(), [](const SegmentInfo& s) {
    return !part_prefix(s.name).empty();
  });
  std::vector<Part> out;
  if (!joined) {
    Part whole;
    whole.program = program_name(meta);
    whole.segments = segments;
    if (!segments.empty()) {
      whole.t0_s = segments.front().t0_s;
      whole.t1_s = segments.back().t1_s;
    }
    out.push_back(std::move(whole));
    return out;
  }
  for (const SegmentInfo& s : segments) {
    const std::string program = part_prefix(s.name);
    if (out.empty() || out.back().program != program) out.push_back({program, {}, s.t0_s, s.t1_s});
    out.back().segments.push_back(s);
    out.back().t1_s = std::max(out.back().t1_s, s.t1_s);
  }
  return out;
}

std::optional<std::string> requirement_unmet(Stage stage, const std::vector<SegmentInfo>& segments,
                                             const Settings& settings) {
  const int statics = static_cast<int>(std::count_if(segments.begin(), segments.end(), is_static));
  switch (stage) {
    case Stage::Direct: {
      const int rates = count_kind(segments, "rate");
      if (statics >= 6 && rates >= 3) return std::nullopt;
      return "stage direct needs at least 6 static segments and 3 rate segments; there are " + std::to_string(statics) +
             " and " + std::to_string(rates) + " (program 'direct' gives them)";
    }
    case Stage::RateSteps: {
      // A ladder: more rate segments than stage 1's six, and statics between them; the estimator
      // itself says which gyro lacks what.
      const int rates = count_kind(segments, "rate");
      if (statics >= 1 && rates >= 12) return std::nullopt;
      return "stage rate-steps needs a ladder of rate segments (three rates or more both ways, at least 12 segments) "
             "and statics between them; there are " + std::to_string(rates) + " rate segments and " +
             std::to_string(statics) + " statics (program 'rate-steps' or 'rate-steps-short' gives them)";
    }
    case Stage::Tumble: {
      // Statics and the moves between them, nothing turning: a tumble.
      const int turning = count_kind(segments, "rate") + count_kind(segments, "sine") + count_kind(segments, "coning");
      if (statics >= 12 && turning == 0) return std::nullopt;
      return "stage tumble needs at least 12 statics through whole turns in vertical planes and no rate or oscillation "
             "segments; there are " + std::to_string(statics) + " statics and " + std::to_string(turning) +
             " turning segments (program 'tumble' or 'tumble-short' gives them)";
    }
    case Stage::LeverArm:
      if (count_kind(segments, "sine") > 0) return std::nullopt;
      return std::string("stage lever-arm needs oscillation (sine) segments; there are none (program 'lever-arm' gives them)");
    case Stage::Thermal: {
      const std::size_t n = cycles_of(segments, settings).size();
      if (n >= 3) return std::nullopt;
      return "stage thermal needs at least 3 table cycles (statics named cycle-NNN/, or --statics-per-cycle); there are " + std::to_string(n) +
             " (program 'thermal' or 'thermal-short' with its chamber profile gives them)";
    }
    case Stage::Navigation:
      if (count_kind(segments, "sine") > 0) return std::nullopt;
      return std::string("stage navigation needs the slow swings and oscillations of the navigation program; there are "
                         "no sine segments (program 'navigation' gives them)");
    case Stage::Noise: {
      const noise::Options o;
      for (const SegmentInfo& s : segments)
        if (is_static(s) && s.t1_s - s.t0_s >= o.min_static_s) return std::nullopt;
      char buf[160];
      std::snprintf(buf, sizeof buf,
                    "stage noise needs a static segment of at least %.0f s; there is none (program 'noise' holds still for 7500 s)",
                    o.min_static_s);
      return std::string(buf);
    }
    case Stage::WarmUp: {
      // One static from power-on (the run's start), long enough for the fit's bins.
      const warm_up::Options o;
      const double needed_s = 60.0 * o.bin_s;
      for (const SegmentInfo& s : segments)
        if (is_static(s) && s.t1_s - s.t0_s >= needed_s) return std::nullopt;
      char buf[200];
      std::snprintf(buf, sizeof buf,
                    "stage warm-up needs a static of at least %.0f s from power-on; there is none (program 'warm-up' "
                    "holds still for 2 h, 'warm-up-short' for 30 min)",
                    needed_s);
      return std::string(buf);
    }
    case Stage::Repeatability: {
      // Power-ons with a static after each: the run's start and two power cycles at least.
      const int cycles = count_kind(segments, "power-cycle");
      if (cycles >= 2 && statics >= 3) return std::nullopt;
      return "stage repeatability needs statics after at least 3 power-ons (2 power-cycle segments or more); there are " +
             std::to_string(cycles) + " power-cycle segments and " + std::to_string(statics) +
             " statics (program 'repeatability' or 'repeatability-short' gives them)";
    }
  }
  return std::string("unknown stage");
}

Feed feed(Stage stage, const RecordingMeta& meta, bool asked, const Settings& settings) {
  const std::vector<Part> all = parts(meta);
  std::vector<const Part*> chosen;
  for (const Part& p : all)
    if (purpose_of_program(p.program) == stage) chosen.push_back(&p);
  std::string unmet;
  if (chosen.empty()) {
    for (const Part& p : all) {
      if (purpose_of_program(p.program) || p.program == "evaluate") continue;  // made for another stage
      if (const auto why = requirement_unmet(stage, p.segments, settings)) {
        unmet = *why;
      } else {
        chosen.push_back(&p);
      }
    }
  }
  Feed f;
  if (chosen.size() == 1 && all.size() == 1) {
    // The whole recording is that part: no window, so nothing before the first segment is lost.
    f.segments = chosen.front()->segments;
    f.source = "the whole recording (program '" + (chosen.front()->program.empty() ? std::string("unnamed") : chosen.front()->program) + "')";
    return f;
  }
  if (chosen.empty()) {
    if (asked) {
      f.segments = meta.segments;
      f.source = "the whole recording";
      return f;
    }
    const StageName& n = names_of(stage);
    f.skipped = unmet.empty() ? std::string("no part of the recording is the ") + n.program + " program" : unmet;
    return f;
  }
  double t0 = chosen.front()->t0_s, t1 = chosen.front()->t1_s;
  // Each program named once, in the order it first comes, with how many parts it made: a
  // thermal run's stage 1 is fed by some 30 parts of 'direct' between the chamber's steps, once
  // listed as 'direct', 'direct', ... 30 times (issue 36, item 7).
  std::vector<std::pair<std::string, int>> programs;
  for (const Part* p : chosen) {
    f.segments.insert(f.segments.end(), p->segments.begin(), p->segments.end());
    t0 = std::min(t0, p->t0_s);
    t1 = std::max(t1, p->t1_s);
    const auto known = std::find_if(programs.begin(), programs.end(), [&](const auto& e) { return e.first == p->program; });
    if (known == programs.end()) {
      programs.emplace_back(p->program, 1);
    } else {
      ++known->second;
    }
  }
  std::string names;
  if (programs.size() == chosen.size()) {  // one part each: "part 'direct'", "parts 'direct', 'lever-arm'"
    for (const auto& [program, count] : programs) names += (names.empty() ? "'" : ", '") + program + "'";
    names = (chosen.size() == 1 ? "part " : "parts ") + names;
  } else {
    for (const auto& [program, count] : programs)
      names += (names.empty() ? "" : ", ") +
               (count == 1 ? "part '" + program + "'" : std::to_string(count) + " parts of '" + program + "'");
  }
  f.t0_ns = nanoseconds(t0 - kLead_s);
  f.t1_ns = nanoseconds(t1);
  f.source = names + " (" + span_text(t0, t1) + ")";
  return f;
}

std::vector<Stage> stages_for_parts(const RecordingMeta& meta) {
  std::vector<Stage> out;
  for (const StageName& n : stage_names())
    if (feed(n.stage, meta, false).skipped.empty()) out.push_back(n.stage);
  return out;
}

void RunDbSource::frames(std::int64_t t0_ns, std::int64_t t1_ns, const std::function<void(const ImuFrame&)>& fn) const {
  db_.for_each_frame(fn, t0_ns, t1_ns);
}

std::vector<TempSample> RunDbSource::temps(std::int64_t t0_ns, std::int64_t t1_ns) const { return db_.temps(t0_ns, t1_ns); }

const char* to_string(Status status) {
  switch (status) {
    case Status::Pending: return "waiting";
    case Status::Running: return "running";
    case Status::Done: return "done";
    case Status::Skipped: return "skipped";
    case Status::Undetermined: return "undetermined";
    case Status::Failed: return "failed";
  }
  return "unknown";
}

// ------------------------------------------------------------------------------------------------
// One stage over its window: fed frame by frame (temperatures before the frames after them),
// asked at the window's end whether it wants another pass over it, then finished.
class Pipeline::Run {
 public:
  virtual ~Run() = default;
  virtual void push(const ImuFrame& f) = 0;
  virtual void push_temp(const TempSample&) {}
  // At the end of the window: true when the stage wants the window again from its start.
  virtual bool another_pass() { return false; }
  virtual void finish(const FrameSource& source, const Feed& feed, Outcome& out) = 0;
  virtual json progress() const { return json::object(); }
};

namespace {

RecordingMeta with_segments(const RecordingMeta& meta, std::vector<SegmentInfo> segments) {
  RecordingMeta m = meta;
  m.segments = std::move(segments);
  return m;
}

class DirectRun final : public Pipeline::Run {
 public:
  DirectRun(const RecordingMeta& meta, const Feed& f, const ImuModel& start, const direct::Options& options)
      : meta_(meta), start_(start), options_(options) {
    const bool has_statics = std::any_of(f.segments.begin(), f.segments.end(), is_static);
    if (has_statics) {
      calibrator_ = std::make_unique<direct::DirectCalibrator>(with_segments(meta, f.segments), options_);
    } else {
      // A recording without a segment list (an imported CSV): the statics are found from the
      // table angles in a first pass.
      detector_.emplace();
    }
  }
  void push(const ImuFrame& f) override {
    if (detector_) {
      detector_->push(f);
    } else {
      calibrator_->push(f);
    }
  }
  bool another_pass() override {
    if (!detector_) return false;
    detected_ = detector_->finish();
    detector_.reset();
    calibrator_ = std::make_unique<direct::DirectCalibrator>(with_segments(meta_, detected_), options_);
    return true;
  }
  void finish(const FrameSource&, const Feed&, Outcome& out) override {
    if (!detected_.empty() || detector_)
      out.notes.push_back("stage direct: the run lists no statics; found " + std::to_string(detected_.size()) +
                          " from the table angles");
    direct::Result r = calibrator_->finish(start_);
    out.notes.insert(out.notes.end(), r.notes.begin(), r.notes.end());
    out.model = r.model;
    out.direct = std::move(r);
  }
  json progress() const override {
    json p = {{"statics", 0}, {"rotations", 0}, {"estimates", json::object()}, {"message", nullptr}};
    if (!calibrator_) return p;
    int statics = 0, rotations = 0;
    for (const auto& iv : calibrator_->intervals()) (iv.is_static ? statics : rotations) += 1;
    p["statics"] = statics;
    p["rotations"] = rotations;
    try {
      const direct::Result r = calibrator_->finish(start_);
      p["estimates"] = estimates_json(r.model);
    } catch (const std::exception& e) {
      // Until every orientation has been seen some coefficient is undetermined; say which.
      p["undetermined"] = true;
      p["message"] = e.what();
    }
    return p;
  }

 private:
  RecordingMeta meta_;
  ImuModel start_;
  direct::Options options_;
  std::optional<direct::SegmentDetector> detector_;
  std::vector<SegmentInfo> detected_;
  std::unique_ptr<direct::DirectCalibrator> calibrator_;
};

}  // namespace

json estimates_json(const ImuModel& model) {
  const std::vector<Coefficient> all = model_coefficients(model);
  // An optional term (nonlinear, delay, proof mass) only where a stage estimated it, i.e. the model
  // carries its uncertainty: elsewhere a row of zeros would say it was estimated.
  std::set<std::string> estimated_groups;
  for (const Coefficient& c : all)
    if (c.sigma > 0.0) estimated_groups.insert(c.group);
  json out = json::object();
  for (const Coefficient& c : all)
    if (!c.optional || estimated_groups.count(c.group)) out[c.key] = json::array({c.value, c.sigma});
  return out;
}

namespace {

// The rate-steps test: the scale factors, their asymmetry and nonlinearity from the ladder; the
// misalignments of the model before it remove the cross-axis Earth rate.
class RateStepsRun final : public Pipeline::Run {
 public:
  RateStepsRun(const RecordingMeta& meta, const Feed& f, const ImuModel& start)
      : estimator_(with_segments(meta, f.segments)), start_(start) {}
  void push(const ImuFrame& f) override { estimator_.push(f); }
  void finish(const FrameSource&, const Feed&, Outcome& out) override {
    rate_steps::Result r = estimator_.finish(start_);
    out.notes.insert(out.notes.end(), r.notes.begin(), r.notes.end());
    out.model = r.model;
    out.rate_steps = std::move(r);
  }
  json progress() const override {
    json p = {{"estimates", json::object()}, {"message", nullptr}};
    try {
      p["estimates"] = estimates_json(estimator_.finish(start_).model);
    } catch (const std::exception& e) {
      // Until a gyro has turned at three rates nothing is determined; say so.
      p["undetermined"] = true;
      p["message"] = e.what();
    }
    return p;
  }

 private:
  rate_steps::RateStepsEstimator estimator_;
  ImuModel start_;
};

// The tumble: the accelerometers' bias, scale, K2, K3 and angles and the gyros' bias and
// g-sensitivity from statics in vertical planes; the gyro scale factors and angles of the model
// before it remove the Earth rate.
class TumbleRun final : public Pipeline::Run {
 public:
  TumbleRun(const RecordingMeta& meta, const Feed& f, const ImuModel& start)
      : estimator_(with_segments(meta, f.segments)), start_(start) {}
  void push(const ImuFrame& f) override { estimator_.push(f); }
  void finish(const FrameSource&, const Feed&, Outcome& out) override {
    tumble::Result r = estimator_.finish(start_);
    out.notes.insert(out.notes.end(), r.notes.begin(), r.notes.end());
    out.model = r.model;
    out.tumble = std::move(r);
  }
  json progress() const override { return {{"statics", estimator_.statics_seen()}}; }

 private:
  tumble::TumbleEstimator estimator_;
  ImuModel start_;
};

class LeverArmRun final : public Pipeline::Run {
 public:
  LeverArmRun(const RecordingMeta& meta, const ImuModel& start) : filter_(meta, start) {}
  void push(const ImuFrame& f) override { filter_.push(f); }
  void finish(const FrameSource&, const Feed&, Outcome& out) override {
    lever::Result r = filter_.finish();
    out.notes.insert(out.notes.end(), r.notes.begin(), r.notes.end());
    out.model = r.model;
    out.lever_arm = std::move(r);
  }

 private:
  lever::LeverArmFilter filter_;
};

class ThermalRun final : public Pipeline::Run {
 public:
  ThermalRun(const RecordingMeta& meta, const Feed& f, const ImuModel& start, const Settings& settings)
      : meta_(meta), start_(start), settings_(settings) {
    const std::vector<SegmentInfo> segments = without_part_prefix(f.segments);
    if (const auto why = requirement_unmet(Stage::Thermal, f.segments, settings)) throw std::invalid_argument(*why);
    const std::vector<thermal::Cycle> cycles = thermal::find_cycles(segments, settings.statics_per_cycle);
    meta_.segments = segments;
    estimator_ = std::make_unique<thermal::CycleEstimator>(meta_, cycles, start_);
  }
  void push(const ImuFrame& f) override { estimator_->push(f); }
  void finish(const FrameSource& source, const Feed& f, Outcome& out) override {
    thermal::Options opt;
    opt.T_ref_C = settings_.thermal_T_ref_C;
    opt.range_lo_C = settings_.thermal_range_lo_C;
    opt.range_hi_C = settings_.thermal_range_hi_C;
    // The rate of each interval is a centred fit: the temperatures reach that far past the window.
    const std::int64_t margin_ns = nanoseconds(opt.rate_half_window_s);
    const std::int64_t t0 = f.t0_ns == kMinNs ? kMinNs : f.t0_ns - margin_ns;
    const std::int64_t t1 = f.t1_ns == kMaxNs ? kMaxNs : f.t1_ns + margin_ns;
    const std::vector<TempSample> temps = source.temps(t0, t1);
    const auto estimates = estimator_->finish();
    thermal::Result r = settings_.thermal_keep_shape ? thermal::refit_constants(meta_, estimates, temps, start_, opt)
                                                     : thermal::calibrate(meta_, estimates, temps, start_, opt);
    out.notes.insert(out.notes.end(), r.notes.begin(), r.notes.end());
    out.model = r.model;
    out.extras.emplace_back("thermal_report", r.report_json);
    out.thermal = std::move(r);
  }

 private:
  RecordingMeta meta_;
  ImuModel start_;
  Settings settings_;
  std::unique_ptr<thermal::CycleEstimator> estimator_;
};

// Stage 3: the navigation-solution filter, `passes` times over the window, each pass from the
// model of the last (online: one pass).
class NavigationRun final : public Pipeline::Run {
 public:
  NavigationRun(const RecordingMeta& meta, const Feed& f, const ImuModel& start, const Settings& settings)
      : meta_(with_segments(meta, f.segments)), settings_(settings), passes_left_(std::max(1, settings.passes)) {
    filter_ = std::make_unique<navfilter::NavCalibrationFilter>(meta_, start, settings_.navigation);
  }
  void push(const ImuFrame& f) override {
    filter_->push(f);
    ++frames_;
  }
  void push_temp(const TempSample& t) override { filter_->push_temp(t); }
  bool another_pass() override {
    result_ = filter_->finish();
    --passes_left_;
    if (passes_left_ <= 0 || !result_->converged) return false;
    filter_ = std::make_unique<navfilter::NavCalibrationFilter>(meta_, result_->model, settings_.navigation);
    ++passes_done_;
    return true;
  }
  void finish(const FrameSource&, const Feed&, Outcome& out) override {
    if (!result_) result_ = filter_->finish();
    const navfilter::Result& r = *result_;
    out.extras.emplace_back("navigation_history", r.history_json());
    char buf[256];
    std::snprintf(buf, sizeof buf, "stage navigation: %s; %lld frames, %lld updates, %lld rejected, %lld restarts, %d pass(es)",
                  r.status.c_str(), static_cast<long long>(r.frames), static_cast<long long>(r.updates),
                  static_cast<long long>(r.rejected), static_cast<long long>(r.restarts), passes_done_ + 1);
    out.notes.emplace_back(buf);
    out.navigation = r;
    if (!r.converged)
      throw std::runtime_error("stage navigation " + r.status + " (estimates up to then are in the run as history)");
    out.model = r.model;
  }
  // The filter as it runs: every calibration state's estimate and sigma, its status, its
  // restarts, and the last update's innovations against their gates (docs/api.md, progress).
  json progress() const override {
    const navfilter::Progress p = filter_->progress();
    json out = {{"frames", frames_},
                {"filter_status", p.status},
                {"updates", p.updates},
                {"rejected", p.rejected},
                {"restarts", p.restarts},
                {"restart_times_s", p.restart_times_s},
                {"estimates", estimates_json(p.model)}};
    if (p.last_measurement) {
      static const char* const kNames[navfilter::MeasurementRecord::kCount] = {
          "velocity_mps.E", "velocity_mps.N", "velocity_mps.U", "position_m.E", "position_m.N",
          "position_m.U",   "attitude_arcsec.E", "attitude_arcsec.N", "attitude_arcsec.U"};
      const navfilter::MeasurementRecord& m = *p.last_measurement;
      json inn = json::object();
      for (std::size_t i = 0; i < navfilter::MeasurementRecord::kCount; ++i) {
        if (!(m.variance[i] > 0)) continue;  // not measured (no attitude measurement)
        const double scale = i >= 6 ? units::kRadToArcsec : 1.0;
        // [innovation, gate]: accepted while |innovation| <= gate.
        inn[kNames[i]] = json::array({m.innovation[i] * scale, p.gate_sigma * std::sqrt(m.variance[i]) * scale});
      }
      out["innovations"] = {{"t_s", m.t_s}, {"values", inn}};
    }
    return out;
  }

 private:
  RecordingMeta meta_;
  Settings settings_;
  int passes_left_, passes_done_ = 0;
  std::int64_t frames_ = 0;
  std::unique_ptr<navfilter::NavCalibrationFilter> filter_;
  std::optional<navfilter::Result> result_;
};

class NoiseRun final : public Pipeline::Run {
 public:
  NoiseRun(const RecordingMeta& meta, const Feed& f, const ImuModel& start)
      : analyzer_(with_segments(meta, f.segments)), start_(start) {}
  void push(const ImuFrame& f) override { analyzer_.push(f); }
  void finish(const FrameSource&, const Feed&, Outcome& out) override {
    noise::Result r;
    try {
      r = analyzer_.finish();
    } catch (const std::exception& e) {
      throw std::runtime_error(std::string(e.what()) + "; " + requirement_unmet(Stage::Noise, {}).value_or(""));
    }
    out.notes.insert(out.notes.end(), r.notes.begin(), r.notes.end());
    out.model = r.apply(start_);
    out.extras.emplace_back("noise_curves", r.curves_json());  // Allan and PSD curves for the plots
    out.noise = std::move(r);
  }

 private:
  noise::NoiseAnalyzer analyzer_;
  ImuModel start_;
};

// The warm-up: each channel's transient from power-on in one static.
class WarmUpRun final : public Pipeline::Run {
 public:
  WarmUpRun(const RecordingMeta& meta, const Feed& f, const ImuModel& start)
      : estimator_(with_segments(meta, f.segments)), start_(start) {}
  void push(const ImuFrame& f) override { estimator_.push(f); }
  void finish(const FrameSource&, const Feed&, Outcome& out) override {
    warm_up::Result r = estimator_.finish(start_);
    out.notes.insert(out.notes.end(), r.notes.begin(), r.notes.end());
    out.model = r.model;
    out.warm_up = std::move(r);
  }
  json progress() const override { return {{"bins", estimator_.bins_seen()}}; }

 private:
  warm_up::WarmUpEstimator estimator_;
  ImuModel start_;
};

// Turn-on to turn-on repeatability: each power-on's static mean, their spread less the noise.
class RepeatabilityRun final : public Pipeline::Run {
 public:
  RepeatabilityRun(const RecordingMeta& meta, const Feed& f, const ImuModel& start)
      : estimator_(with_segments(meta, f.segments)), start_(start) {}
  void push(const ImuFrame& f) override { estimator_.push(f); }
  void finish(const FrameSource&, const Feed&, Outcome& out) override {
    repeatability::Result r = estimator_.finish(start_);
    out.notes.insert(out.notes.end(), r.notes.begin(), r.notes.end());
    out.model = r.model;
    out.repeatability = std::move(r);
  }
  json progress() const override { return {{"turn_ons", estimator_.turn_ons_seen()}}; }

 private:
  repeatability::RepeatabilityEstimator estimator_;
  ImuModel start_;
};

}  // namespace

namespace {

// The repeatability's figures per channel (deg/h, ug) and each power-on's static mean less the
// mean over the power-ons, with its sigma (for a plot against the power-on).
json repeatability_json(const repeatability::Result& r) {
  constexpr double ug_per_mps2 = 1e6 / units::kStandardGravity_mps2;
  static const char* const kAxes[3] = {"x", "y", "z"};
  json channels = json::array();
  repeatability::Vector6d mean = repeatability::Vector6d::Zero();
  for (const repeatability::TurnOn& t : r.turn_ons) mean += t.mean / static_cast<double>(r.turn_ons.size());
  for (const repeatability::Channel& ch : r.channels) {
    const double k = ch.gyro ? units::kRadpsToDph : ug_per_mps2;
    channels.push_back({{"sensor", ch.gyro ? "gyro" : "accel"}, {"axis", kAxes[ch.axis]}, {"unit", ch.gyro ? "dph" : "ug"},
                        {"repeatability", json::array({ch.repeatability * k, ch.repeatability_sigma * k})},
                        {"interval_68", json::array({ch.lo68 * k, ch.hi68 * k})},
                        {"interval_997", json::array({ch.lo997 * k, ch.hi997 * k})},
                        {"spread", ch.spread * k}, {"noise", ch.noise * k}});
  }
  json turn_ons = json::array();
  for (const repeatability::TurnOn& t : r.turn_ons) {
    json offset = json::array(), sigma = json::array();
    for (int c = 0; c < 6; ++c) {
      const double k = c < 3 ? units::kRadpsToDph : ug_per_mps2;
      offset.push_back((t.mean[c] - mean[c]) * k);
      sigma.push_back(t.mean_sigma[c] * k);
    }
    turn_ons.push_back({{"index", t.index}, {"segment", t.segment}, {"t0_s", t.t0_s}, {"duration_s", t.duration_s},
                        {"offset", offset}, {"offset_sigma", sigma}});
  }
  return {{"channels", channels}, {"turn_ons", turn_ons}};
}

// The warm-up's figures per channel, in the units people read (deg/h, ug), and its bins for the
// plot of each channel's output from power-on with the fitted transient.
json warm_up_json(const warm_up::Result& r) {
  constexpr double ug_per_mps2 = 1e6 / units::kStandardGravity_mps2;
  static const char* const kAxes[3] = {"x", "y", "z"};
  json channels = json::array();
  json deviation = json::array();
  for (std::size_t c = 0; c < 6; ++c) {
    const warm_up::Channel& ch = r.channels[c];
    const double k = ch.gyro ? units::kRadpsToDph : ug_per_mps2;
    const char* unit = ch.gyro ? "dph" : "ug";
    channels.push_back({{"sensor", ch.gyro ? "gyro" : "accel"},
                        {"axis", kAxes[ch.axis]},
                        {"unit", unit},
                        {"detected", ch.detected},
                        {"resolved", ch.resolved},
                        {"amplitude", json::array({ch.amplitude * k, ch.amplitude_sigma * k})},
                        {"time_constant_s", json::array({ch.time_constant_s, ch.time_constant_sigma_s})},
                        {"settle_time_s", json::array({ch.settle_time_s, ch.settle_time_sigma_s})},
                        {"band", ch.band * k},
                        {"residual_rms", ch.residual_rms * k},
                        {"chi2_gain", ch.chi2_gain}});
    json d = json::array();
    for (double v : r.deviation[c]) d.push_back(v * k);
    deviation.push_back(d);
  }
  return {{"duration_s", r.duration_s}, {"channels", channels}, {"t_s", r.t_s}, {"deviation", deviation}};
}

// The rate-steps test's figures (docs/api.md, results): per gyro, every [value, sigma] it gives,
// the degree scores and the steps (for the scale-against-rate plot).
json rate_steps_json(const rate_steps::Result& r) {
  static const char* const kAxes[3] = {"x", "y", "z"};
  json axes = json::array();
  for (const rate_steps::Axis& a : r.axes) {
    if (!a.tested) continue;
    json nonlinear = json::array();
    for (int k = 0; k < a.degree; ++k)
      nonlinear.push_back(json::array({a.nonlinear_ppm[static_cast<std::size_t>(k)], a.nonlinear_sigma_ppm[static_cast<std::size_t>(k)]}));
    json scores = json::array();
    for (const rate_steps::DegreeScore& d : a.scores)
      scores.push_back({{"degree", d.degree}, {"held_back_rms_ppm", d.held_back_rms_ppm}});
    json steps = json::array();
    for (const rate_steps::Step& st : a.steps) {
      double model_sigma = 0;
      const double model = a.scale_ppm_at(st.rate_dps, &model_sigma);
      steps.push_back({{"segment", st.segment}, {"rate_dps", st.rate_dps}, {"angle_deg", st.angle_deg},
                       {"duration_s", st.duration_s}, {"scale_ppm", json::array({st.scale_ppm, st.sigma_ppm})},
                       {"model_ppm", json::array({model, model_sigma})}, {"fit_residual_ppm", st.fit_residual_ppm}});
    }
    axes.push_back({{"axis", kAxes[a.axis]},
                    {"bias_dph", json::array({a.bias_dph, a.bias_sigma_dph})},
                    {"scale_pos_ppm", json::array({a.scale_pos_ppm, a.scale_pos_sigma_ppm})},
                    {"scale_neg_ppm", json::array({a.scale_neg_ppm, a.scale_neg_sigma_ppm})},
                    {"asymmetry_ppm", json::array({a.asymmetry_ppm, a.asymmetry_sigma_ppm})},
                    {"degree", a.degree},
                    {"scale_nonlinear_ppm", nonlinear},
                    {"degree_scores", scores},
                    {"full_scale_dps", a.full_scale_dps},
                    {"nonlinearity_ppm_fs", json::array({a.nonlinearity_ppm_fs, a.nonlinearity_sigma_ppm_fs})},
                    {"nonlinearity_at_dps", a.nonlinearity_at_dps},
                    {"residual_rms_ppm", a.residual_rms_ppm},
                    {"steps", steps}});
  }
  return {{"axes", axes}};
}

// The tumble's figures: its residuals and every static's specific force, output and residuals
// (for a plot of the residuals against the tumble angle).
json tumble_json(const tumble::Result& r) {
  constexpr double ug_per_mps2 = 1e6 / units::kStandardGravity_mps2;
  auto vec = [](const Eigen::Vector3d& v, double scale) { return json::array({v[0] * scale, v[1] * scale, v[2] * scale}); };
  json positions = json::array();
  for (const tumble::Position& p : r.positions)
    positions.push_back({{"segment", p.segment}, {"duration_s", p.duration_s}, {"f_o_mps2", vec(p.f_o_mps2, 1.0)},
                         {"accel_residual_ug", vec(p.accel_residual_mps2, ug_per_mps2)},
                         {"gyro_residual_dph", vec(p.gyro_residual_radps, units::kRadpsToDph)}});
  return {{"accel_residual_rms_ug", vec(r.accel_residual_rms_mps2, ug_per_mps2)},
          {"gyro_residual_rms_dph", vec(r.gyro_residual_rms_radps, units::kRadpsToDph)},
          {"positions", positions}};
}

}  // namespace

// ------------------------------------------------------------------------------------------------
json Outcome::report() const {
  const StageName& n = names_of(stage);
  json j = {{"stage", n.name}, {"status", to_string(status)}, {"source", source}, {"notes", notes}, {"frames", frames}};
  if (!message.empty()) j["message"] = message;
  if (direct) {
    j["statics"] = direct->statics;
    j["rotations"] = direct->rotations;
    j["static_time_s"] = direct->static_time_s;
    j["accel_residual_rms_mps2"] = direct->accel_residual_rms_mps2;
    j["gyro_residual_rms_rad"] = direct->gyro_residual_rms_rad;
  }
  if (rate_steps) j["rate_steps"] = rate_steps_json(*rate_steps);
  if (tumble) j["tumble"] = tumble_json(*tumble);
  if (warm_up) j["warm_up"] = warm_up_json(*warm_up);
  if (repeatability) j["repeatability"] = repeatability_json(*repeatability);
  if (lever_arm) {
    j["updates"] = lever_arm->updates;
    json mm = json::array(), sg = json::array();
    for (int i = 0; i < 9; ++i) {
      mm.push_back(lever_arm->state_m[i] * 1e3);
      sg.push_back(lever_arm->sigma_m[i] * 1e3);
    }
    j["proof_masses_mm"] = mm;
    j["proof_masses_sigma_mm"] = sg;
  }
  if (thermal) {
    j["cycles_total"] = thermal->cycles_total;
    j["cycles_used"] = thermal->cycles_used;
  }
  if (navigation) {
    const navfilter::Result& r = *navigation;
    j["filter_status"] = r.status;
    j["converged"] = r.converged;
    j["updates"] = r.updates;
    j["rejected"] = r.rejected;
    j["restarts"] = r.restarts;
    json reduction = json::object();
    for (const navfilter::Block& b : navfilter::state::kAll) {
      json v = json::array();
      for (int i = 0; i < b.size; ++i) {
        const double s0 = r.sigma0[b.index + i], s1 = r.sigma_final[b.index + i];
        v.push_back(s1 > 0 ? s0 / s1 : 0.0);
      }
      reduction[b.name] = v;
    }
    j["uncertainty_reduction"] = reduction;
    j["relative_gyro_delays_us"] = {{"tau_yx", r.tau_yx_s * 1e6}, {"sigma_tau_yx", r.sigma_tau_yx_s * 1e6},
                                    {"tau_zx", r.tau_zx_s * 1e6}, {"sigma_tau_zx", r.sigma_tau_zx_s * 1e6}};
  }
  if (noise) {
    j["longest_static_s"] = noise->longest_static_s;
    j["total_static_s"] = noise->total_static_s;
  }
  if (model && status == Status::Done) {
    j["estimates"] = estimates_json(*model);
    j["model"] = json::parse(imu_model_to_json_text(*model));
  }
  return j;
}

// ------------------------------------------------------------------------------------------------
Pipeline::Pipeline(const RecordingMeta& meta, std::vector<Stage> stages, bool asked, ImuModel start, Settings settings)
    : meta_(meta), settings_(std::move(settings)), model_(std::move(start)) {
  std::vector<Stage> ordered;
  for (const StageName& n : stage_names())
    if (std::find(stages.begin(), stages.end(), n.stage) != stages.end()) ordered.push_back(n.stage);
  if (model_.frame != "instrument" &&
      std::any_of(ordered.begin(), ordered.end(), [](Stage s) { return s != Stage::Navigation && s != Stage::Noise && s != Stage::WarmUp &&
                                                                 s != Stage::Repeatability; }))
    throw std::invalid_argument("the start model is in the " + model_.frame +
                                " frame: give the instrument-frame model (the body-frame form is an output of stage "
                                "navigation)");
  for (Stage s : ordered) {
    feeds_.push_back(feed(s, meta_, asked, settings_));
    Outcome o;
    o.stage = s;
    o.source = feeds_.back().source;
    if (!feeds_.back().skipped.empty()) {
      o.status = Status::Skipped;
      o.message = feeds_.back().skipped;
    }
    outcomes_.push_back(std::move(o));
  }
}

Pipeline::~Pipeline() = default;

bool Pipeline::finished() const { return active_ >= outcomes_.size(); }

bool Pipeline::advance(const FrameSource& source, std::int64_t available_t_ns, bool final) {
  while (active_ < outcomes_.size()) {
    Outcome& out = outcomes_[active_];
    const Feed& f = feeds_[active_];
    if (out.status == Status::Skipped) {
      ++active_;
      continue;
    }
    try {
      if (!run_) {
        switch (out.stage) {
          case Stage::Direct: run_ = std::make_unique<DirectRun>(meta_, f, model_, settings_.direct); break;
          case Stage::RateSteps: run_ = std::make_unique<RateStepsRun>(meta_, f, model_); break;
          case Stage::Tumble: run_ = std::make_unique<TumbleRun>(meta_, f, model_); break;
          case Stage::LeverArm: run_ = std::make_unique<LeverArmRun>(meta_, model_); break;
          case Stage::Thermal: run_ = std::make_unique<ThermalRun>(meta_, f, model_, settings_); break;
          case Stage::Navigation: run_ = std::make_unique<NavigationRun>(meta_, f, model_, settings_); break;
          case Stage::Noise: run_ = std::make_unique<NoiseRun>(meta_, f, model_); break;
          case Stage::WarmUp: run_ = std::make_unique<WarmUpRun>(meta_, f, model_); break;
          case Stage::Repeatability: run_ = std::make_unique<RepeatabilityRun>(meta_, f, model_); break;
        }
        out.status = Status::Running;
        feeder_ = Feeder(f.t0_ns, f.t1_ns);
      }
      feeder_.feed(
          source, available_t_ns, [&](const TempSample& t) { run_->push_temp(t); },
          [&](const ImuFrame& frame) {
            run_->push(frame);
            out.program_time_s = seconds(frame.t_ns);
            ++out.frames;
          });
      if (!final && !feeder_.complete(available_t_ns)) return false;  // the window is not complete yet
      // Before the run finishes: a filter's finish() hands its running figures over to its result.
      keep_last_progress(out);
      if (run_->another_pass()) {
        feeder_.rewind();
        continue;
      }
      run_->finish(source, f, out);
      out.status = Status::Done;
      model_ = *out.model;
    } catch (const direct::UndeterminedError& e) {
      out.status = Status::Undetermined;
      out.message = e.what();
    } catch (const std::exception& e) {
      out.status = Status::Failed;
      out.message = e.what();
    }
    if (out.last_progress.is_null()) keep_last_progress(out);  // a run that failed while fed
    run_.reset();
    ++active_;
  }
  return true;
}

void Pipeline::keep_last_progress(Outcome& out) const {
  if (!run_) return;
  try {
    out.last_progress = run_->progress();
  } catch (const std::exception&) {
    return;  // a run that failed may have nothing to say of itself
  }
  if (out.last_progress.is_object()) out.last_progress.erase("undetermined");  // its status is the outcome's
}

json Pipeline::progress(Stage stage) const {
  for (std::size_t i = 0; i < outcomes_.size(); ++i) {
    const Outcome& o = outcomes_[i];
    if (o.stage != stage) continue;
    json p = i == active_ && run_ ? run_->progress() : o.last_progress.is_object() ? o.last_progress : json::object();
    p["status"] = to_string(o.status);
    p["program_time_s"] = o.program_time_s;
    p["source"] = o.source;
    if (!o.message.empty()) p["message"] = o.message;
    if (o.status == Status::Done && o.model) p["estimates"] = estimates_json(*o.model);
    if (p.contains("undetermined")) {
      p.erase("undetermined");
      p["status"] = o.frames == 0 ? "waiting" : "undetermined";
    }
    return p;
  }
  return json::object();
}

void Feeder::feed(const FrameSource& source, std::int64_t available_t_ns,
                  const std::function<void(const TempSample&)>& temp, const std::function<void(const ImuFrame&)>& frame) {
  const std::int64_t upto = std::min(available_t_ns, t1_ns_);
  const std::int64_t from = fed_t_ns_ ? *fed_t_ns_ + 1 : t0_ns_;
  if (from > upto) return;
  if (!temps_read_to_ns_ || upto > *temps_read_to_ns_) {
    const std::int64_t t0 = temps_read_to_ns_ ? *temps_read_to_ns_ + 1 : kMinNs;
    for (const TempSample& t : source.temps(t0, upto)) pending_temps_.push_back(t);
    temps_read_to_ns_ = upto;
  }
  std::size_t next_temp = 0;
  source.frames(from, upto, [&](const ImuFrame& f) {
    while (next_temp < pending_temps_.size() && pending_temps_[next_temp].t_ns <= f.t_ns) temp(pending_temps_[next_temp++]);
    frame(f);
    fed_t_ns_ = f.t_ns;
  });
  pending_temps_.erase(pending_temps_.begin(), pending_temps_.begin() + static_cast<std::ptrdiff_t>(next_temp));
}

void Feeder::rewind() {
  fed_t_ns_.reset();
  pending_temps_.clear();
  temps_read_to_ns_.reset();
}

evaluate::Result evaluate_recording(const RecordingMeta& meta, const FrameSource& source, const ImuModel& model) {
  return evaluate::evaluate_model(
      meta, model, [&](const auto& fn, std::int64_t t0, std::int64_t t1) { source.frames(t0, t1, fn); },
      source.temps(kMinNs, kMaxNs));
}

std::vector<Outcome> run_to_end(const storage::RunDb& db, std::vector<Stage> stages, bool asked, const ImuModel& start,
                                const Settings& settings) {
  return run_to_end(db.meta(), RunDbSource(db), std::move(stages), asked, start, settings);
}

std::vector<Outcome> run_to_end(const RecordingMeta& meta, const FrameSource& source, std::vector<Stage> stages,
                                bool asked, const ImuModel& start, const Settings& settings) {
  Pipeline p(meta, std::move(stages), asked, start, settings);
  p.advance(source, kMaxNs, true);
  return p.outcomes();
}

Calibration calibration_of(const std::vector<Outcome>& outcomes) {
  Calibration c;
  for (const Outcome& o : outcomes) {
    c.reports[names_of(o.stage).estimator] = o.report();
    if (o.status == Status::Done) c.model = o.model;  // as Pipeline::model(): the last stage done
  }
  return c;
}

void ProgressSource::frames(std::int64_t t0_ns, std::int64_t t1_ns, const std::function<void(const ImuFrame&)>& fn) const {
  std::int64_t n = 0;
  inner_.frames(t0_ns, t1_ns, [&](const ImuFrame& f) {
    fn(f);
    if ((++n & 0xFFFF) == 0 && report_ && end_s_ > 0)
      report_(from_ + span_ * std::clamp(static_cast<double>(f.t_ns) * 1e-9 / end_s_, 0.0, 1.0));
  });
}

double end_of_program_s(const RecordingMeta& meta) {
  double end_s = 0.0;
  for (const SegmentInfo& s : meta.segments) end_s = std::max(end_s, s.t1_s);
  return end_s;
}

}  // namespace imucal::pipeline
