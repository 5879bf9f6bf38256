#include "pipeline/stages/warm_up/warm_up_stage.hpp"

#include <utility>

#include "estimators/warm_up.hpp"
#include "pipeline/stage.hpp"

namespace imucal::pipeline::warm_up_stage {

using nlohmann::json;
using namespace stage_util;

namespace {

// The warm-up: each channel's transient from power-on in one static.
class WarmUpRun final : public StageRun {
 public:
  WarmUpRun(const RecordingMeta& meta, const Feed& f, const ImuModel& start)
      : estimator_(with_segments(meta, f.segments)), start_(start) {}
  void push(const ImuFrame& f) override { estimator_.push(f); }
  void finish(const FrameSource&, const Feed&, Outcome& out) override {
    warm_up::Result r = estimator_.finish(start_);
    add_notes(out, r.notes);
    out.model = r.model;
    out.result = std::move(r);
  }
  json progress() const override { return {{"bins", estimator_.bins_seen()}}; }

 private:
  warm_up::WarmUpEstimator estimator_;
  ImuModel start_;
};

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

}  // namespace

std::optional<std::string> requirement(const std::vector<SegmentInfo>& segments, const Settings&) {
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

std::unique_ptr<StageRun> make_run(const StageContext& c) { return std::make_unique<WarmUpRun>(c.meta, c.feed, c.start); }

void report(const Outcome& o, json& j) {
  if (const auto* r = o.result_as<warm_up::Result>()) j["warm_up"] = warm_up_json(*r);
}

std::optional<json> report_file(const Outcome& o) {
  const auto* r = o.result_as<warm_up::Result>();
  if (!r) return std::nullopt;
  return warm_up_json(*r);
}

void print(const Outcome& o, std::FILE* out) {
  const auto* result = o.result_as<warm_up::Result>();
  if (result) {
    // Each channel's transient from power-on, in deg/h and ug.
    std::fprintf(out, "warm-up over %.0f s from power-on:\n  %-8s %24s %22s %22s %10s\n", result->duration_s, "channel",
                "amplitude", "time constant s", "settle time s", "band");
    for (const warm_up::Channel& ch : result->channels) {
      const double k = ch.gyro ? units::kRadpsToDph : 1e6 / units::kStandardGravity_mps2;
      const char* unit = ch.gyro ? "deg/h" : "ug";
      std::fprintf(out, "  %-6s %c %11.5f +- %7.5f %-5s", ch.gyro ? "gyro" : "accel", "xyz"[ch.axis], ch.amplitude * k,
                  ch.amplitude_sigma * k, unit);
      if (ch.detected)
        std::fprintf(out, " %9.0f +- %7.0f %11.0f +- %7.0f %7.4g %s\n", ch.time_constant_s, ch.time_constant_sigma_s,
                    ch.settle_time_s, ch.settle_time_sigma_s, ch.band * k, unit);
      else
        std::fprintf(out, " no transient above the noise\n");
    }
  }
}

}  // namespace imucal::pipeline::warm_up_stage
