// What a stage's folder (pipeline/stages/<stage>/) builds on: the runner the pipeline feeds, and the
// small helpers several stages share (segment counts, a recording with the feed's segments).
#pragma once

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <string>
#include <utility>
#include <vector>

#include <nlohmann/json.hpp>

#include "core/recording.hpp"
#include "core/units.hpp"
#include "pipeline/pipeline.hpp"

namespace imucal::pipeline {

// One stage over its window: fed frame by frame (temperatures before the frames after them),
// asked at the window's end whether it wants another pass over it, then finished.
class StageRun {
 public:
  StageRun() = default;
  StageRun(const StageRun&) = delete;
  StageRun& operator=(const StageRun&) = delete;
  virtual ~StageRun() = default;
  virtual void push(const ImuFrame& f) = 0;
  virtual void push_temp(const TempSample&) {}
  // At the end of the window: true when the stage wants the window again from its start.
  virtual bool another_pass() { return false; }
  // Sets the outcome's model, result, notes and extras; throws when the stage cannot give a model.
  virtual void finish(const FrameSource& source, const Feed& feed, Outcome& out) = 0;
  // The live figures (docs/api.md, progress); "undetermined": true while nothing is determined.
  virtual nlohmann::json progress() const { return nlohmann::json::object(); }
};

namespace stage_util {

// The unbounded ends of a feed's window (a stage fed the whole recording).
inline constexpr std::int64_t kMinNs = std::numeric_limits<std::int64_t>::min();
inline constexpr std::int64_t kMaxNs = std::numeric_limits<std::int64_t>::max();

inline double seconds(std::int64_t t_ns) { return static_cast<double>(t_ns) / units::kNsPerS; }
inline std::int64_t nanoseconds(double t_s) { return std::llround(t_s * units::kNsPerS); }

// A tilt is a static for the stages: the table holds still.
inline bool is_static(const SegmentInfo& s) { return s.kind == "static" || s.kind == "tilt"; }
inline int count_statics(const std::vector<SegmentInfo>& segments) {
  return static_cast<int>(std::count_if(segments.begin(), segments.end(), is_static));
}
inline int count_kind(const std::vector<SegmentInfo>& segments, const char* kind) {
  return static_cast<int>(
      std::count_if(segments.begin(), segments.end(), [&](const SegmentInfo& s) { return s.kind == kind; }));
}

// The recording as the stage sees it: only the segments that feed it.
inline RecordingMeta with_segments(const RecordingMeta& meta, std::vector<SegmentInfo> segments) {
  RecordingMeta m = meta;
  m.segments = std::move(segments);
  return m;
}

// A result's notes after the outcome's own.
inline void add_notes(Outcome& out, const std::vector<std::string>& notes) {
  out.notes.insert(out.notes.end(), notes.begin(), notes.end());
}

}  // namespace stage_util

}  // namespace imucal::pipeline
