#include "pipeline/pipeline.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <set>
#include <stdexcept>

#include "core/coefficients.hpp"
#include "core/units.hpp"
#include "pipeline/stage.hpp"
#include "storage/run_db.hpp"

namespace imucal::pipeline {

using nlohmann::json;
using namespace stage_util;

namespace {

// A part's window opens this much before its first segment: stage 1 needs the frame before its
// first static, the filters a start on the frame grid.
constexpr double kLead_s = 1.0;

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

std::string span_text(double t0_s, double t1_s) {
  char buf[64];
  std::snprintf(buf, sizeof buf, "t=%.0f..%.0f s", t0_s, t1_s);
  return buf;
}

}  // namespace

std::optional<Stage> purpose_of_program(std::string_view program) {
  for (const StageDescriptor& s : stage_registry())
    if (program == s.program || (s.short_program && program == s.short_program)) return s.stage;
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
  return names_of(stage).requirement(segments, settings);
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
    const StageDescriptor& n = names_of(stage);
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
  for (const StageDescriptor& s : stage_registry())
    if (feed(s.stage, meta, false).skipped.empty()) out.push_back(s.stage);
  return out;
}

void RunDbSource::frames(std::int64_t t0_ns, std::int64_t t1_ns, const std::function<void(const ImuFrame&)>& fn) const {
  db_.for_each_frame(fn, t0_ns, t1_ns);
}

std::vector<TempSample> RunDbSource::temps(std::int64_t t0_ns, std::int64_t t1_ns) const { return db_.temps(t0_ns, t1_ns); }

void MemorySource::frames(std::int64_t t0_ns, std::int64_t t1_ns, const std::function<void(const ImuFrame&)>& fn) const {
  auto it = std::lower_bound(frames_.begin(), frames_.end(), t0_ns,
                             [](const ImuFrame& f, std::int64_t t) { return f.t_ns < t; });
  for (; it != frames_.end() && it->t_ns <= t1_ns; ++it) fn(*it);
}

std::vector<TempSample> MemorySource::temps(std::int64_t t0_ns, std::int64_t t1_ns) const {
  std::vector<TempSample> out;
  for (const TempSample& t : temps_)
    if (t.t_ns >= t0_ns && t.t_ns <= t1_ns) out.push_back(t);
  return out;
}

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

// ------------------------------------------------------------------------------------------------
json Outcome::report() const {
  const StageDescriptor& n = names_of(stage);
  json j = {{"stage", n.name}, {"status", to_string(status)}, {"source", source}, {"notes", notes}, {"frames", frames}};
  if (!message.empty()) j["message"] = message;
  n.report(*this, j);
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
  for (const StageDescriptor& s : stage_registry())
    if (std::find(stages.begin(), stages.end(), s.stage) != stages.end()) ordered.push_back(s.stage);
  if (model_.frame != "instrument" &&
      std::any_of(ordered.begin(), ordered.end(), [](Stage s) { return !names_of(s).any_frame_start; }))
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
        run_ = names_of(out.stage).make_run(StageContext{meta_, f, model_, settings_});
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
