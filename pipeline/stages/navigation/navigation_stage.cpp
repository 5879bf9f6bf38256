#include "pipeline/stages/navigation/navigation_stage.hpp"

#include <cstdio>
#include <stdexcept>
#include <utility>

#include "estimators/nav_filter.hpp"
#include "pipeline/stage.hpp"

namespace imucal::pipeline::navigation_stage {

using nlohmann::json;
using namespace stage_util;

namespace {

// Stage 3: the navigation-solution filter, `passes` times over the window, each pass from the
// model of the last (online: one pass).
class NavigationRun final : public StageRun {
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
    out.result = r;
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


}  // namespace

std::optional<std::string> requirement(const std::vector<SegmentInfo>& segments, const Settings&) {
  if (count_kind(segments, "sine") > 0) return std::nullopt;
  return std::string("stage navigation needs the slow swings and oscillations of the navigation program; there are "
                     "no sine segments (program 'navigation' gives them)");
}

std::unique_ptr<StageRun> make_run(const StageContext& c) { return std::make_unique<NavigationRun>(c.meta, c.feed, c.start, c.settings); }

// The filter's counts, each state's uncertainty reduction sqrt(P0/Pk) and the relative gyro delays.
void report(const Outcome& o, json& j) {
  const auto* result = o.result_as<navfilter::Result>();
  if (!result) return;
  const navfilter::Result& r = *result;
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

void print(const Outcome& o, std::FILE* out) {
  const auto* result = o.result_as<navfilter::Result>();
  if (result) {
    const navfilter::Result& r = *result;
    std::fprintf(out, "  uncertainty reduction sqrt(P0/Pk) per state (1 = the data said nothing):\n");
    for (const navfilter::Block& b : navfilter::state::kAll) {
      std::fprintf(out, "    %-24s", b.name);
      for (int i = 0; i < b.size; ++i) {
        const double s0 = r.sigma0[b.index + i], s1 = r.sigma_final[b.index + i];
        std::fprintf(out, " %8.1f", s1 > 0 ? s0 / s1 : 0.0);
      }
      std::fprintf(out, "\n");
    }
    std::fprintf(out, "  relative gyro delays: tau_yx %.3f us (sigma %.3f), tau_zx %.3f us (sigma %.3f)\n", r.tau_yx_s * 1e6,
                r.sigma_tau_yx_s * 1e6, r.tau_zx_s * 1e6, r.sigma_tau_zx_s * 1e6);
  }
}

}  // namespace imucal::pipeline::navigation_stage
