#include "pipeline/stages/repeatability/repeatability_stage.hpp"

#include <utility>

#include "estimators/repeatability.hpp"
#include "pipeline/stage.hpp"

namespace imucal::pipeline::repeatability_stage {

using nlohmann::json;
using namespace stage_util;

namespace {

// Turn-on to turn-on repeatability: each power-on's static mean, their spread less the noise.
class RepeatabilityRun final : public StageRun {
 public:
  RepeatabilityRun(const RecordingMeta& meta, const Feed& f, const ImuModel& start)
      : estimator_(with_segments(meta, f.segments)), start_(start) {}
  void push(const ImuFrame& f) override { estimator_.push(f); }
  void finish(const FrameSource&, const Feed&, Outcome& out) override {
    repeatability::Result r = estimator_.finish(start_);
    add_notes(out, r.notes);
    out.model = r.model;
    out.result = std::move(r);
  }
  json progress() const override { return {{"turn_ons", estimator_.turn_ons_seen()}}; }

 private:
  repeatability::RepeatabilityEstimator estimator_;
  ImuModel start_;
};

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

}  // namespace

std::optional<std::string> requirement(const std::vector<SegmentInfo>& segments, const Settings&) {
  // Power-ons with a static after each: the run's start and two power cycles at least.
  const int statics = count_statics(segments);
  const int cycles = count_kind(segments, "power-cycle");
  if (cycles >= 2 && statics >= 3) return std::nullopt;
  return "stage repeatability needs statics after at least 3 power-ons (2 power-cycle segments or more); there are " +
         std::to_string(cycles) + " power-cycle segments and " + std::to_string(statics) +
         " statics (program 'repeatability' or 'repeatability-short' gives them)";
}

std::unique_ptr<StageRun> make_run(const StageContext& c) { return std::make_unique<RepeatabilityRun>(c.meta, c.feed, c.start); }

void report(const Outcome& o, json& j) {
  if (const auto* r = o.result_as<repeatability::Result>()) j["repeatability"] = repeatability_json(*r);
}

std::optional<json> report_file(const Outcome& o) {
  const auto* r = o.result_as<repeatability::Result>();
  if (!r) return std::nullopt;
  return repeatability_json(*r);
}

void print(const Outcome& o, std::FILE* out) {
  const auto* result = o.result_as<repeatability::Result>();
  if (result) {
    const repeatability::Result& r = *result;
    std::fprintf(out, "turn-on to turn-on repeatability over %zu power-ons:\n  %-8s %24s %12s %12s\n", r.turn_ons.size(),
                "channel", "repeatability (1 sigma)", "spread", "noise");
    for (const repeatability::Channel& ch : r.channels) {
      const double k = ch.gyro ? units::kRadpsToDph : 1e6 / units::kStandardGravity_mps2;
      std::fprintf(out, "  %-6s %c %11.5f +- %7.5f %-5s %12.5f %12.5f\n", ch.gyro ? "gyro" : "accel", "xyz"[ch.axis],
                  ch.repeatability * k, ch.repeatability_sigma * k, ch.gyro ? "deg/h" : "ug", ch.spread * k, ch.noise * k);
    }
  }
}

}  // namespace imucal::pipeline::repeatability_stage
