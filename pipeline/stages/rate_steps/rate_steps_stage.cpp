#include "pipeline/stages/rate_steps/rate_steps_stage.hpp"

#include <exception>
#include <utility>

#include "estimators/rate_steps.hpp"
#include "pipeline/stage.hpp"

namespace imucal::pipeline::rate_steps_stage {

using nlohmann::json;
using namespace stage_util;

namespace {

// The rate-steps test: the scale factors, their asymmetry and nonlinearity from the ladder; the
// misalignments of the model before it remove the cross-axis Earth rate.
class RateStepsRun final : public StageRun {
 public:
  RateStepsRun(const RecordingMeta& meta, const Feed& f, const ImuModel& start)
      : estimator_(with_segments(meta, f.segments)), start_(start) {}
  void push(const ImuFrame& f) override { estimator_.push(f); }
  void finish(const FrameSource&, const Feed&, Outcome& out) override {
    rate_steps::Result r = estimator_.finish(start_);
    add_notes(out, r.notes);
    out.model = r.model;
    out.result = std::move(r);
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

}  // namespace

std::optional<std::string> requirement(const std::vector<SegmentInfo>& segments, const Settings&) {
  // A ladder: more rate segments than stage 1's six, and statics between them; the estimator
  // itself says which gyro lacks what.
  const int statics = count_statics(segments);
  const int rates = count_kind(segments, "rate");
  if (statics >= 1 && rates >= 12) return std::nullopt;
  return "stage rate-steps needs a ladder of rate segments (three rates or more both ways, at least 12 segments) "
         "and statics between them; there are " + std::to_string(rates) + " rate segments and " +
         std::to_string(statics) + " statics (program 'rate-steps' or 'rate-steps-short' gives them)";
}

std::unique_ptr<StageRun> make_run(const StageContext& c) { return std::make_unique<RateStepsRun>(c.meta, c.feed, c.start); }

void report(const Outcome& o, json& j) {
  if (const auto* r = o.result_as<rate_steps::Result>()) j["rate_steps"] = rate_steps_json(*r);
}

std::optional<json> report_file(const Outcome& o) {
  const auto* r = o.result_as<rate_steps::Result>();
  if (!r) return std::nullopt;
  return rate_steps_json(*r);
}

void print(const Outcome& o, std::FILE* out) {
  const auto* result = o.result_as<rate_steps::Result>();
  if (result) {
    static const char* const kAxes[3] = {"x", "y", "z"};
    for (const rate_steps::Axis& a : result->axes) {
      if (!a.tested) continue;
      std::fprintf(out, "gyro %s: scale + %.3f +- %.3f ppm, - %.3f +- %.3f ppm, asymmetry %.3f +- %.3f ppm; IEEE 952 "
                  "nonlinearity %.3f +- %.3f ppm of %.0f deg/s (at %+.0f deg/s); nonlinear degree %d",
                  kAxes[a.axis], a.scale_pos_ppm, a.scale_pos_sigma_ppm, a.scale_neg_ppm, a.scale_neg_sigma_ppm,
                  a.asymmetry_ppm, a.asymmetry_sigma_ppm, a.nonlinearity_ppm_fs, a.nonlinearity_sigma_ppm_fs,
                  a.full_scale_dps, a.nonlinearity_at_dps, a.degree);
      for (int k = 0; k < a.degree; ++k)
        std::fprintf(out, "%s c%d %.3f +- %.3f", k == 0 ? ":" : ",", k + 1, a.nonlinear_ppm[static_cast<std::size_t>(k)],
                    a.nonlinear_sigma_ppm[static_cast<std::size_t>(k)]);
      std::fprintf(out, "\n  %10s %12s %9s %12s %10s\n", "rate deg/s", "scale ppm", "sigma", "model ppm", "resid ppm");
      for (const rate_steps::Step& st : a.steps)
        std::fprintf(out, "  %+10.2f %12.3f %9.3f %12.3f %10.3f\n", st.rate_dps, st.scale_ppm, st.sigma_ppm,
                    a.scale_ppm_at(st.rate_dps), st.fit_residual_ppm);
    }
  }
}

}  // namespace imucal::pipeline::rate_steps_stage
