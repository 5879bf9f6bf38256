#include "pipeline/stages/noise/noise_stage.hpp"

#include <exception>
#include <stdexcept>
#include <utility>

#include "estimators/noise.hpp"
#include "pipeline/stage.hpp"

namespace imucal::pipeline::noise_stage {

using nlohmann::json;
using namespace stage_util;

namespace {

class NoiseRun final : public StageRun {
 public:
  NoiseRun(const RecordingMeta& meta, const Feed& f, const ImuModel& start)
      : analyzer_(with_segments(meta, f.segments)), start_(start) {}
  void push(const ImuFrame& f) override { analyzer_.push(f); }
  void finish(const FrameSource&, const Feed&, Outcome& out) override {
    noise::Result r;
    try {
      r = analyzer_.finish();
    } catch (const std::exception& e) {
      throw std::runtime_error(std::string(e.what()) + "; " + requirement({}, Settings{}).value_or(""));
    }
    add_notes(out, r.notes);
    out.model = r.apply(start_);
    out.extras.emplace_back("noise_curves", r.curves_json());  // Allan and PSD curves for the plots
    out.result = std::move(r);
  }

 private:
  noise::NoiseAnalyzer analyzer_;
  ImuModel start_;
};


}  // namespace

std::optional<std::string> requirement(const std::vector<SegmentInfo>& segments, const Settings&) {
  const noise::Options o;
  for (const SegmentInfo& s : segments)
    if (is_static(s) && s.t1_s - s.t0_s >= o.min_static_s) return std::nullopt;
  char buf[160];
  std::snprintf(buf, sizeof buf,
                "stage noise needs a static segment of at least %.0f s; there is none (program 'noise' holds still for 7500 s)",
                o.min_static_s);
  return std::string(buf);
}

std::unique_ptr<StageRun> make_run(const StageContext& c) { return std::make_unique<NoiseRun>(c.meta, c.feed, c.start); }

void report(const Outcome& o, json& j) {
  const auto* r = o.result_as<noise::Result>();
  if (!r) return;
  j["longest_static_s"] = r->longest_static_s;
  j["total_static_s"] = r->total_static_s;
}

void print(const Outcome&, std::FILE*) {}  // its notes say it all

}  // namespace imucal::pipeline::noise_stage
