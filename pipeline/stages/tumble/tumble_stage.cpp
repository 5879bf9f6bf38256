#include "pipeline/stages/tumble/tumble_stage.hpp"

#include <utility>

#include "core/expect_value.hpp"
#include "core/imu_model.hpp"
#include "estimators/tumble.hpp"
#include "pipeline/stage.hpp"

namespace imucal::pipeline::tumble_stage {

using nlohmann::json;
using namespace stage_util;

namespace {

// The tumble: the accelerometers' bias, scale, K2, K3 and angles and the gyros' bias and
// g-sensitivity from statics in vertical planes; the gyro scale factors and angles of the model
// before it remove the Earth rate.
class TumbleRun final : public StageRun {
 public:
  TumbleRun(const RecordingMeta& meta, const Feed& f, const ImuModel& start)
      : estimator_(with_segments(meta, f.segments)), start_(start) {}
  void push(const ImuFrame& f) override { estimator_.push(f); }
  void finish(const FrameSource&, const Feed&, Outcome& out) override {
    tumble::Result r = estimator_.finish(start_);
    add_notes(out, r.notes);
    out.model = r.model;
    out.result = std::move(r);
  }
  json progress() const override { return {{"statics", estimator_.statics_seen()}}; }

 private:
  tumble::TumbleEstimator estimator_;
  ImuModel start_;
};

// The tumble's figures: its residuals and every static's specific force, output and residuals
// (for a plot of the residuals against the tumble angle).
json tumble_json(const tumble::Result& r) {
  constexpr double ug_per_mps2 = 1e6 / units::kStandardGravity_mps2;
  auto vec = [](const Eigen::Vector3d& v, double scale) { return json::array({v[0] * scale, v[1] * scale, v[2] * scale}); };
  json positions = json::array();
  for (const tumble::Position& p : r.positions)
    positions.push_back({{"segment", p.segment}, {"duration_s", p.duration_s}, {"f_o_mps2", vec(p.f_o_mps2, 1.0)},
                         {"accel_residual_ug", vec(p.accel_residual_mps2, ug_per_mps2)},
                         {"gyro_residual_dph", vec(p.gyro_residual_radps, units::kRadpsToDph)}});
  return {{"accel_residual_rms_ug", vec(r.accel_residual_rms_mps2, ug_per_mps2)},
          {"gyro_residual_rms_dph", vec(r.gyro_residual_rms_radps, units::kRadpsToDph)},
          {"positions", positions}};
}

}  // namespace

std::optional<std::string> requirement(const std::vector<SegmentInfo>& segments, const Settings&) {
  // Statics and the moves between them, nothing turning: a tumble.
  const int statics = count_statics(segments);
  const int turning = count_kind(segments, "rate") + count_kind(segments, "sine") + count_kind(segments, "coning");
  if (statics >= 12 && turning == 0) return std::nullopt;
  return "stage tumble needs at least 12 statics through whole turns in vertical planes and no rate or oscillation "
         "segments; there are " + std::to_string(statics) + " statics and " + std::to_string(turning) +
         " turning segments (program 'tumble' or 'tumble-short' gives them)";
}

std::unique_ptr<StageRun> make_run(const StageContext& c) { return std::make_unique<TumbleRun>(c.meta, c.feed, c.start); }

void report(const Outcome& o, json& j) {
  if (const auto* r = o.result_as<tumble::Result>()) j["tumble"] = tumble_json(*r);
}

void print(const Outcome& o, std::FILE* out) {
  const auto* result = o.result_as<tumble::Result>();
  if (result) {
    // Every coefficient the tumble gives, with its sigma, in the units of the model file.
    const ImuModel& m = result->model;
    const ImuErrorSet& s = expect_value(m.sigma, "the tumble's sigmas");  // the tumble gives every sigma it prints
    static const char* const kAxes[3] = {"x", "y", "z"};
    constexpr double ug = 1e6 / units::kStandardGravity_mps2;
    std::fprintf(out, "  %-6s %22s %18s %18s %18s %26s\n", "accel", "bias ug", "scale ppm", "K2 ug/g^2", "K3 ug/g^3", "residual rms ug");
    for (int j = 0; j < 3; ++j)
      std::fprintf(out, "  %-6s %12.3f +- %6.3f %9.3f +- %5.3f %9.3f +- %5.3f %9.3f +- %5.3f %26.3f\n", kAxes[j], m.accel.bias_mps2[j] * ug,
                  s.accel.bias_mps2[j] * ug, m.accel.scale[j] * 1e6, s.accel.scale[j] * 1e6, m.accel.k2_per_g[j] * 1e6,
                  s.accel.k2_per_g[j] * 1e6, m.accel.k3_per_g2[j] * 1e6, s.accel.k3_per_g2[j] * 1e6,
                  result->accel_residual_rms_mps2[j] * ug);
    std::fprintf(out, "  %-6s %22s   g-sensitivity deg/h/g along o x, y, z\n", "gyro", "bias deg/h");
    for (int j = 0; j < 3; ++j) {
      std::fprintf(out, "  %-6s %12.5f +- %7.5f", kAxes[j], m.gyro.bias_radps[j] * units::kRadpsToDph, s.gyro.bias_radps[j] * units::kRadpsToDph);
      for (int k = 0; k < 3; ++k)
        std::fprintf(out, " %9.5f +- %7.5f", m.gyro.g_sensitivity_radps_per_g(j, k) * units::kRadpsToDph,
                    s.gyro.g_sensitivity_radps_per_g(j, k) * units::kRadpsToDph);
      std::fprintf(out, "\n");
    }
  }
}

}  // namespace imucal::pipeline::tumble_stage
