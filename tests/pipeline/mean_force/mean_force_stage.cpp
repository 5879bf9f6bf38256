#include "tests/pipeline/mean_force/mean_force_stage.hpp"

#include <cstdint>
#include <stdexcept>
#include <string>

#include "pipeline/stage.hpp"

namespace imucaltest::mean_force_stage {

using imucal::ImuFrame;
using imucal::ImuModel;
using imucal::pipeline::Outcome;
using nlohmann::json;

namespace {

// Sums the velocity increments and the time they span: their ratio is the mean specific force.
class MeanForceRun final : public imucal::pipeline::StageRun {
 public:
  explicit MeanForceRun(const ImuModel& start) : start_(start) {}
  void push(const ImuFrame& f) override {
    // The first frame's increment ends at its time stamp: the span starts one frame interval
    // before it, which the second frame tells.
    if (frames_ == 1) first_t_ns_ -= f.t_ns - first_t_ns_;
    if (frames_ == 0) first_t_ns_ = f.t_ns;
    sum_dv_mps_ += f.dv_mps;
    last_t_ns_ = f.t_ns;
    ++frames_;
  }
  void finish(const imucal::pipeline::FrameSource&, const imucal::pipeline::Feed&, Outcome& out) override {
    if (frames_ < 2) throw std::runtime_error("stage mean-force: fewer than 2 frames");
    Result r;
    r.frames = frames_;
    r.mean_specific_force_mps2 = sum_dv_mps_ / imucal::pipeline::stage_util::seconds(last_t_ns_ - first_t_ns_);
    out.notes.push_back("stage mean-force: " + std::to_string(frames_) + " frames");
    out.model = start_;  // it estimates no coefficient
    out.result = r;
  }
  json progress() const override { return {{"frames", frames_}}; }

 private:
  ImuModel start_;
  Eigen::Vector3d sum_dv_mps_ = Eigen::Vector3d::Zero();
  std::int64_t first_t_ns_ = 0, last_t_ns_ = 0;
  long long frames_ = 0;
};

}  // namespace

std::optional<std::string> requirement(const std::vector<imucal::SegmentInfo>& segments,
                                       const imucal::pipeline::Settings&) {
  if (imucal::pipeline::stage_util::count_statics(segments) > 0) return std::nullopt;
  return std::string("stage mean-force needs a static segment; there is none");
}

std::unique_ptr<imucal::pipeline::StageRun> make_run(const imucal::pipeline::StageContext& c) {
  return std::make_unique<MeanForceRun>(c.start);
}

void report(const Outcome& o, json& j) {
  const auto* r = o.result_as<Result>();
  if (!r) return;
  const Eigen::Vector3d& f = r->mean_specific_force_mps2;
  j["mean_specific_force_mps2"] = json::array({f.x(), f.y(), f.z()});
}

void print(const Outcome& o, std::FILE* out) {
  if (const auto* r = o.result_as<Result>())
    std::fprintf(out, "mean specific force %.6f %.6f %.6f m/s^2\n", r->mean_specific_force_mps2.x(),
                 r->mean_specific_force_mps2.y(), r->mean_specific_force_mps2.z());
}

}  // namespace imucaltest::mean_force_stage
