#include "estimators/evaluate.hpp"

#include <algorithm>
#include <cmath>
#include <stdexcept>

#include <Eigen/Dense>

#include "core/earth.hpp"
#include "estimators/navigation_run.hpp"

namespace imucal::evaluate {

double SchulerFit::amplitude() const { return std::hypot(c1, c2); }

double schuler_amplitude(const std::vector<double>& t_s, const std::vector<double>& y, double g_mps2) {
  return fit_schuler(t_s, y, g_mps2, false).amplitude();
}

SchulerFit fit_schuler(const std::vector<double>& t_s, const std::vector<double>& y, double g_mps2,
                       bool with_azimuth_ramp) {
  if (t_s.size() < 5) return {};
  const double nu = std::sqrt(g_mps2 / earth::kA_m);
  const auto n = static_cast<Eigen::Index>(t_s.size());
  Eigen::MatrixXd A(n, with_azimuth_ramp ? 4 : 3);
  Eigen::VectorXd b(n);
  for (Eigen::Index i = 0; i < n; ++i) {
    const double t = t_s[static_cast<std::size_t>(i)] - t_s.front();
    A(i, 0) = 1.0;
    A(i, 1) = std::cos(nu * t);
    A(i, 2) = std::sin(nu * t);
    // A vertical gyro drift turns the azimuth, and the Earth rate seen through the growing azimuth
    // error is a horizontal drift growing with time: dV ~ (t - sin(nu t) / nu). Without this term
    // it leaks into the sine term and passes for an accelerometer error.
    if (with_azimuth_ramp) A(i, 3) = t - std::sin(nu * t) / nu;
    b(i) = y[static_cast<std::size_t>(i)];
  }
  const Eigen::VectorXd c = A.colPivHouseholderQr().solve(b);
  return {c[0], c[1], c[2]};
}

Result evaluate_model(const RecordingMeta& meta, const ImuModel& model, const FrameRange& frames,
                      const std::vector<TempSample>& temps) {
  Result out;
  const double g = earth::site_gravity_mps2(meta.site);
  const double nu = std::sqrt(g / earth::kA_m);
  // A tilt segment is the hold after the move into the tilt; coning is its own segment.
  std::vector<SegmentInfo> judged;
  for (const SegmentInfo& s : meta.segments)
    if (s.kind == "tilt" || s.kind == "coning") judged.push_back(s);
  if (judged.empty())
    throw std::invalid_argument("evaluate: the recording has no tilt or coning segments (record the evaluate program)");
  for (const SegmentInfo& s : judged) {
    SegmentResult sr;
    sr.name = s.name;
    sr.kind = s.kind;
    sr.t0_s = s.t0_s;
    sr.t1_s = s.t1_s;
    std::vector<double> t, ve, vn;
    nav::NavigationRun run(meta, model, 5.0, [&](const nav::NavErrorSample& e) {
      t.push_back(e.t_s);
      ve.push_back(e.dv_n_mps.x());
      vn.push_back(e.dv_n_mps.y());
    });
    // Start one second before the segment so the navigation is initialised at rest or in motion
    // exactly as the table says, then judge the whole segment.
    const std::int64_t t_start_ns = std::llround((s.t0_s - 1.0) * 1e9);
    // Temperatures from a little more than the thermal rate's window (120 s) before the start, so
    // that dT/dt is known from the first frame; then each sample before the frames after it.
    auto next_temp = std::lower_bound(temps.begin(), temps.end(), t_start_ns - 150'000'000'000LL,
                                      [](const TempSample& x, std::int64_t t_ns) { return x.t_ns < t_ns; });
    frames(
        [&](const ImuFrame& f) {
          while (next_temp != temps.end() && next_temp->t_ns <= f.t_ns) run.push_temp(*next_temp++);
          run.push(f);
        },
        t_start_ns, std::llround(s.t1_s * 1e9));
    const nav::NavSummary sum = run.finish();
    sr.max_velocity_error_mps = sum.max_velocity_error_mps;
    sr.max_position_error_m = sum.max_position_error_m;
    // The amplitude as method.md defines it; the implied errors from the separated terms:
    // (da/g) sqrt(R g) = da / nu in the sine term, dw R in the cosine term.
    sr.schuler_amplitude_e_mps = schuler_amplitude(t, ve, g);
    sr.schuler_amplitude_n_mps = schuler_amplitude(t, vn, g);
    sr.amplitude_mps = std::max(sr.schuler_amplitude_e_mps, sr.schuler_amplitude_n_mps);
    const SchulerFit fe = fit_schuler(t, ve, g, true), fn = fit_schuler(t, vn, g, true);
    sr.implied_accel_error_mps2 = std::hypot(fe.c2, fn.c2) * nu;
    sr.implied_gyro_drift_radps = std::hypot(fe.c1, fn.c1) / earth::kA_m;
    if (s.kind == "tilt") {
      out.tilt_amplitude_mps = std::max(out.tilt_amplitude_mps, sr.amplitude_mps);
      out.implied_accel_error_mps2 = std::max(out.implied_accel_error_mps2, sr.implied_accel_error_mps2);
    } else {
      out.coning_amplitude_mps = std::max(out.coning_amplitude_mps, sr.amplitude_mps);
      out.implied_gyro_drift_radps = std::max(out.implied_gyro_drift_radps, sr.implied_gyro_drift_radps);
    }
    sr.t_s = std::move(t);
    sr.ve_mps = std::move(ve);
    sr.vn_mps = std::move(vn);
    out.segments.push_back(std::move(sr));
  }
  return out;
}

}  // namespace imucal::evaluate
