#include "pipeline/stages/direct/direct_stage.hpp"

#include <algorithm>
#include <optional>
#include <utility>

#include "estimators/direct_calibration.hpp"
#include "pipeline/stage.hpp"

namespace imucal::pipeline::direct_stage {

using nlohmann::json;
using namespace stage_util;

namespace {

class DirectRun final : public StageRun {
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
    add_notes(out, r.notes);
    out.model = r.model;
    out.result = std::move(r);
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

std::optional<std::string> requirement(const std::vector<SegmentInfo>& segments, const Settings&) {
  const int statics = count_statics(segments);
  const int rates = count_kind(segments, "rate");
  if (statics >= 6 && rates >= 3) return std::nullopt;
  return "stage direct needs at least 6 static segments and 3 rate segments; there are " + std::to_string(statics) +
         " and " + std::to_string(rates) + " (program 'direct' gives them)";
}

std::unique_ptr<StageRun> make_run(const StageContext& c) {
  return std::make_unique<DirectRun>(c.meta, c.feed, c.start, c.settings.direct);
}

void report(const Outcome& o, json& j) {
  const auto* r = o.result_as<direct::Result>();
  if (!r) return;
  j["statics"] = r->statics;
  j["rotations"] = r->rotations;
  j["static_time_s"] = r->static_time_s;
  j["accel_residual_rms_mps2"] = r->accel_residual_rms_mps2;
  j["gyro_residual_rms_rad"] = r->gyro_residual_rms_rad;
}

void print(const Outcome&, std::FILE*) {}  // its notes say it all

}  // namespace imucal::pipeline::direct_stage
