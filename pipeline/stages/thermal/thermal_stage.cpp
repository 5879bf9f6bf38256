#include "pipeline/stages/thermal/thermal_stage.hpp"

#include <exception>
#include <stdexcept>
#include <utility>

#include "estimators/thermal.hpp"
#include "pipeline/stage.hpp"

namespace imucal::pipeline::thermal_stage {

using nlohmann::json;
using namespace stage_util;

namespace {

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

class ThermalRun final : public StageRun {
 public:
  ThermalRun(const RecordingMeta& meta, const Feed& f, const ImuModel& start, const Settings& settings)
      : meta_(meta), start_(start), settings_(settings) {
    const std::vector<SegmentInfo> segments = without_part_prefix(f.segments);
    if (const auto why = requirement(f.segments, settings)) throw std::invalid_argument(*why);
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
    add_notes(out, r.notes);
    out.model = r.model;
    out.extras.emplace_back("thermal_report", r.report_json);
    out.result = std::move(r);
  }

 private:
  RecordingMeta meta_;
  ImuModel start_;
  Settings settings_;
  std::unique_ptr<thermal::CycleEstimator> estimator_;
};

}  // namespace

std::optional<std::string> requirement(const std::vector<SegmentInfo>& segments, const Settings& settings) {
  const std::size_t n = cycles_of(segments, settings).size();
  if (n >= 3) return std::nullopt;
  return "stage thermal needs at least 3 table cycles (statics named cycle-NNN/, or --statics-per-cycle); there are " +
         std::to_string(n) + " (program 'thermal' or 'thermal-short' with its chamber profile gives them)";
}

std::unique_ptr<StageRun> make_run(const StageContext& c) {
  return std::make_unique<ThermalRun>(c.meta, c.feed, c.start, c.settings);
}

// The full thermal report (docs/thermal.md) is the estimator's own, kept as a run extra; the
// results carry the cycle counts.
void report(const Outcome& o, json& j) {
  const auto* r = o.result_as<thermal::Result>();
  if (!r) return;
  j["cycles_total"] = r->cycles_total;
  j["cycles_used"] = r->cycles_used;
}

std::optional<json> report_file(const Outcome& o) {
  const auto* r = o.result_as<thermal::Result>();
  if (!r) return std::nullopt;
  return json::parse(r->report_json);
}

void print(const Outcome& o, std::FILE* out) {
  const auto* result = o.result_as<thermal::Result>();
  if (result) {
    const thermal::Result& r = *result;
    const json figures = json::parse(r.report_json);
    std::fprintf(out, "stage thermal: %d of %d cycles used, T_ref %.1f C; largest deviation over the run (%s):\n",
                r.cycles_used, r.cycles_total, figures.at("T_ref_C").get<double>(),
                figures.at("residual_source").get<std::string>().c_str());
    std::fprintf(out, "  %-28s %14s %14s\n", "coefficient", "before", "compensated");
    for (const char* g : thermal::groups())
      std::fprintf(out, "  %-28s %14.6g %14.6g\n", g, figures.at("before").value(g, 0.0), figures.at("residual").value(g, 0.0));
  }
}

}  // namespace imucal::pipeline::thermal_stage
