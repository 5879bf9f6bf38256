// Judging a calibration the way the seed does: free-inertial navigation on the table, restarted
// from the table at each tilt and coning segment, and the Schuler oscillation of the horizontal
// velocity error as the yardstick: tilts give the residual accelerometer error
// (dV = (da/g) sqrt(R g) sin(nu_s t)), coning the residual gyro drift (dV = dw R (1 - cos nu_s t)).
#pragma once

#include <functional>
#include <string>
#include <vector>

#include "core/imu_model.hpp"
#include "core/recording.hpp"

namespace imucal::evaluate {

struct SegmentResult {
  std::string name, kind;  // kind: tilt or coning
  double t0_s = 0, t1_s = 0;
  double schuler_amplitude_e_mps = 0, schuler_amplitude_n_mps = 0;
  double amplitude_mps = 0;        // the larger of the two channels
  double implied_accel_error_mps2 = 0;  // from the sine term (judged on tilts)
  double implied_gyro_drift_radps = 0;  // from the cosine term (judged on coning)
  double max_velocity_error_mps = 0, max_position_error_m = 0;
  // The navigation's horizontal velocity error every 5 s of the segment (for the Schuler plots).
  std::vector<double> t_s, ve_mps, vn_mps;
};

struct Result {
  std::vector<SegmentResult> segments;
  double tilt_amplitude_mps = 0, coning_amplitude_mps = 0;  // worst over the segments of each kind
  double implied_accel_error_mps2 = 0, implied_gyro_drift_radps = 0;
};

// Fit c0 + c1 cos(nu t) + c2 sin(nu t) to y(t), t from the first sample (method.md). The Schuler
// amplitude is sqrt(c1^2 + c2^2). Started from the table at t = 0, a constant accelerometer error
// shows only in the sine term ((da/g) sqrt(R g) sin) and a constant gyro drift only in the cosine
// term (dw R (1 - cos)): the implied errors are read from those terms, so that a drift during a
// tilt is not taken for an accelerometer error.
struct SchulerFit {
  double c0 = 0, c1 = 0, c2 = 0;
  double amplitude() const;
};
// with_azimuth_ramp adds the ramp a vertical gyro drift causes through the Earth rate.
SchulerFit fit_schuler(const std::vector<double>& t_s, const std::vector<double>& y, double g_mps2,
                       bool with_azimuth_ramp);
double schuler_amplitude(const std::vector<double>& t_s, const std::vector<double>& y, double g_mps2);

using FrameRange = std::function<void(const std::function<void(const ImuFrame&)>&, std::int64_t t0_ns,
                                      std::int64_t t1_ns)>;

// Segments of kind tilt and coning are judged; a recording with neither is an error. `temps` (the
// run's temperature samples in time order) drive the model's thermal compensation, if it has a
// section; without them its coefficients are those at T_ref.
Result evaluate_model(const RecordingMeta& meta, const ImuModel& model, const FrameRange& frames,
                      const std::vector<TempSample>& temps = {});

}  // namespace imucal::evaluate
