// Stage 1 of the method (seed ch. 2): calibration by direct measurements. Accelerometers from the
// static positions in the gravity field; gyros from the statics against the Earth rate and from
// rest-to-rest rotations against the table's angle increments (Earth rate along the path included);
// sigmas from the residuals and the design; white-noise densities from the statics; the body frame.
// Pure: frames are pushed in, the result comes out; the same code runs online and offline.
#pragma once

#include <optional>
#include <stdexcept>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "core/imu_model.hpp"
#include "core/recording.hpp"
#include "estimators/table_reference.hpp"

namespace imucal::direct {

// Static and moving intervals found from the table angles, for recordings without `segments`:
// static where no axis moves by more than `still_deg` between frames for at least `min_static_s`.
class SegmentDetector {
 public:
  explicit SegmentDetector(double still_deg = 1e-6, double min_static_s = 10.0, double settle_s = 1.0)
      : still_deg_(still_deg), min_static_s_(min_static_s), settle_s_(settle_s) {}
  void push(const ImuFrame& f);
  std::vector<SegmentInfo> finish();

 private:
  void close_run();
  double still_deg_, min_static_s_, settle_s_;
  bool have_prev_ = false;
  Eigen::Vector3d prev_deg_ = Eigen::Vector3d::Zero();
  double run_t0_s_ = 0, run_t1_s_ = 0, prev_t_s_ = 0;
  bool in_run_ = false;
  std::vector<SegmentInfo> statics_;
};

struct Options {
  double gap_factor = 1.5;       // a frame interval above this many nominal periods is a gap
  double min_rotation_rad = 0.5; // a rest-to-rest interval must turn at least this much to be used
};

// One accumulated interval: a static or a rest-to-rest rotation between two statics.
struct Interval {
  std::string name;
  bool is_static = false;
  double t0_s = 0, t1_s = 0;
  double T_s = 0;                       // sum of frame intervals inside
  long long frames = 0;
  Eigen::Vector3d sum_dtheta = Eigen::Vector3d::Zero(), sum_dv = Eigen::Vector3d::Zero();
  Eigen::Vector3d sumsq_dtheta = Eigen::Vector3d::Zero(), sumsq_dv = Eigen::Vector3d::Zero();
  Eigen::Vector3d ref_pos_rad = Eigen::Vector3d::Zero();  // integral of the positive parts of w_io_o
  Eigen::Vector3d ref_neg_rad = Eigen::Vector3d::Zero();  // integral of the negative parts
  Eigen::Vector3d f_o_mps2 = Eigen::Vector3d::Zero();     // statics: specific force in o
  Eigen::Vector3d moved_axes_rad = Eigen::Vector3d::Zero();  // |total angle change| per table axis
  // For the nonlinear terms a start model fixes (CONVENTIONS.md, "Nonlinear terms"): the integral
  // of the specific force at rest in o (the gyros' g-sensitivity), and per axis k the sums of
  // q_k^m times the reference increment, q_k = |w_k| / kGyroNonlinearityRate_radps, m = 1, 2, 3
  // (the gyro scale nonlinearity's angle is row k of scale_nonlinear times row k of these).
  Eigen::Vector3d f_dt_o = Eigen::Vector3d::Zero();
  Eigen::Matrix3d nonlinear_moments_rad = Eigen::Matrix3d::Zero();
  bool gap = false;
};

// The intervals stage 1 solves with: the statics and the usable rest-to-rest rotations, and a
// note for each rotation left out and why. One selection for the solution and for whoever needs
// its design (stage 2 weighs each interval's temperature by it).
struct Selection {
  std::vector<const Interval*> statics, rotations;
  std::vector<std::string> notes;
};
Selection select_intervals(const std::vector<Interval>& intervals, const Options& options = {});

// One unknown of a sensor's least squares: a bias, a scale factor (gyro + and -, or the
// accelerometer's), or a misalignment angle of the sensor's row of D.
struct Column {
  enum class Kind { Bias, ScalePos, ScaleNeg, Scale, Angle } kind = Kind::Bias;
  double Misalignment::*angle = nullptr;  // Kind::Angle
  const char* angle_name = "";            // "xy" .. "zy", Kind::Angle
};

// Stage 1's weighted least squares of one sensor (gyro or accelerometer `axis`), linearised at
// the given errors (their nonlinear terms, which stage 1 does not estimate, taken as known and
// removed from the measurements): rows are intervals (accelerometers: the statics; gyros: the statics, then the
// rotations), b the measured residual of each row, w its weight. Solving it at the errors it
// returns is what DirectCalibrator::finish iterates to.
struct SensorDesign {
  bool gyro = true;
  int axis = 0;
  std::vector<Column> columns;
  std::vector<const Interval*> rows;
  Eigen::MatrixXd A;
  Eigen::VectorXd b, w;
  // The coefficient behind column c, "gyro.bias_dph.x" as imucal names them everywhere (JSON
  // units in the name; the design itself is SI).
  std::string key(std::size_t c) const;
};
SensorDesign gyro_design(int axis, const Selection& selection, const GyroErrors& at);
SensorDesign accel_design(int axis, const Selection& selection, const AccelErrors& at);
// The SI value a column estimates, in the errors of its triad.
double& coefficient(GyroErrors& g, const Column& c, int axis);
double& coefficient(AccelErrors& a, const Column& c, int axis);

struct Result {
  ImuModel model;                    // instrument frame, with sigma
  std::vector<std::string> notes;    // what was used, what was left out and why
  int statics = 0, rotations = 0;
  double static_time_s = 0;
  double accel_residual_rms_mps2 = 0, gyro_residual_rms_rad = 0;
};

// Thrown when the recording cannot determine a coefficient: names the coefficients and the
// motion that would determine them.
class UndeterminedError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

class DirectCalibrator {
 public:
  // meta.segments must list the statics (use SegmentDetector first when the recording has none).
  DirectCalibrator(const RecordingMeta& meta, const Options& options = {});
  void push(const ImuFrame& frame);
  Result finish(const ImuModel& seed_model = {}) const;
  const std::vector<Interval>& intervals() const { return intervals_; }

 private:
  void open_interval(const std::string& name, bool is_static, double t0_s);
  RecordingMeta meta_;
  Options options_;
  std::vector<SegmentInfo> statics_;
  std::size_t next_static_ = 0;
  table_reference::FrameReference reference_;
  double g_mps2_;
  double dt_nominal_s_;
  std::vector<Interval> intervals_;
  Interval* current_ = nullptr;
  bool have_prev_ = false;
  ImuFrame prev_;
};

// The same model in the body frame built on the accelerometer axes (X = accel x, Y in the accel
// x-y plane): misalignments relative to b and body_to_instrument_arcsec.
ImuModel to_body_frame(const ImuModel& instrument_model);

}  // namespace imucal::direct
