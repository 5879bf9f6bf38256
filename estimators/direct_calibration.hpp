// Stage 1 of the method (seed ch. 2): calibration by direct measurements. Accelerometers from the
// static positions in the gravity field; gyros from the statics against the Earth rate and from
// rest-to-rest rotations against the table's angle increments (Earth rate along the path included);
// sigmas from the residuals and the design, combined with the type B sources (the table's
// certificate, the site's g, the start model's nonlinear terms) into an uncertainty budget;
// white-noise densities from the statics; the body frame.
// Pure: frames are pushed in, the result comes out; the same code runs online and offline.
#pragma once

#include <map>
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

// Stage 1's accuracy limits (docs/calibration.md, "Stage 1's uncertainty budget"): the largest
// error of each coefficient group a stage-1 calibration is accepted with; the tests judge stage 1
// by them and `imucal plan` derives the table accuracy a program needs from them.
struct Limits {
  double gyro_bias_dph = 0.002;
  double gyro_scale_ppm = 0.5;        // scale_pos_ppm and scale_neg_ppm
  double gyro_angle_arcsec = 0.3;     // misalignment_arcsec
  double accel_bias_mps2 = 1e-5;
  double accel_scale_ppm = 1.5;
  double accel_angle_arcsec = 0.5;
};

struct Options {
  double gap_factor = 1.5;       // a frame interval above this many nominal periods is a gap
  double min_rotation_rad = 0.5; // a rest-to-rest interval must turn at least this much to be used
  // The site's g's standard uncertainty for the budget, m/s^2; absent: earth::site_gravity_sigma_mps2
  // (measured or normal gravity).
  std::optional<double> gravity_sigma_mps2;
  // The type B sources (the table's certificate, the site's g, the start model's terms) in sigma
  // and the budget; false: the fit's own sigma alone, for a caller comparing runs on one bench
  // (stage 2's cycles: the table's and the g's errors are the same in every cycle, so they move
  // no slope and must not flatten the cycles' weights).
  bool type_b = true;
};

// The sums of an interval that come from the table's reference, not from the IMU: they move when
// the table's geometry or the site's g does, so the budget accumulates them once more for each
// type B perturbation of the reference (ReferencePerturbation).
struct ReferenceSums {
  Eigen::Vector3d ref_pos_rad = Eigen::Vector3d::Zero();  // integral of the positive parts of w_io_o
  Eigen::Vector3d ref_neg_rad = Eigen::Vector3d::Zero();  // integral of the negative parts
  Eigen::Vector3d f_o_mps2 = Eigen::Vector3d::Zero();     // statics: specific force in o
  // For the nonlinear terms a start model fixes (CONVENTIONS.md, "Nonlinear terms"): the integral
  // of the specific force at rest in o (the gyros' g-sensitivity), and per axis k the sums of
  // q_k^m times the reference increment, q_k = |w_k| / kGyroNonlinearityRate_radps, m = 1, 2, 3
  // (the gyro scale nonlinearity's angle is row k of scale_nonlinear times row k of these).
  Eigen::Vector3d f_dt_o = Eigen::Vector3d::Zero();
  Eigen::Matrix3d nonlinear_moments_rad = Eigen::Matrix3d::Zero();
};

// The budget's names of the start model's terms a stage takes as known without estimating them
// (CONVENTIONS.md, "Nonlinear terms"): stage 1's and stage 3's.
namespace start_model_source {
inline constexpr const char* kGyroScaleNonlinear = "start_model.gyro.scale_nonlinear_ppm";
inline constexpr const char* kGyroGSensitivity = "start_model.gyro.g_sensitivity_dph_per_g";
inline constexpr const char* kAccelK2 = "start_model.accel.k2_ug_per_g2";
inline constexpr const char* kAccelK3 = "start_model.accel.k3_ug_per_g3";
}  // namespace start_model_source

// One type B source of the reference moved by its standard uncertainty (issue 34): the
// recording's description with one table-geometry parameter (or one quadrature of an encoder
// harmonic) or the site's g moved by its 1-sigma, and the budget source it counts under. The
// shift of stage 1's solution when its intervals are accumulated with this reference is that
// parameter's contribution to each coefficient (stage 1's least squares is linear in the
// references, so the shift is its sensitivity times the sigma, to first order).
struct ReferencePerturbation {
  std::string source;  // "table.outer_tilt_arcsec", "table.encoder_error_arcsec.inner", "site.gravity_mps2"
  RecordingMeta meta;
  double sigma = 0.0;  // the 1-sigma it is moved by, in the source's unit (arcsec; m/s^2 for the g)
};
// Every parameter the table's certificate gives a 1-sigma for (table.sigma), about the geometry it
// gives (the ideal table when it gives none); an encoder harmonic as its two quadratures, the one
// in phase with the certified harmonic with the amplitude's sigma, the other with the amplitude
// times the phase's sigma when the geometry gives the harmonic, else (phase unknown) with the
// amplitude's sigma too. And the site's g moved by gravity_sigma_mps2 (none when 0).
std::vector<ReferencePerturbation> reference_perturbations(const RecordingMeta& meta, double gravity_sigma_mps2);
// The site's g's standard uncertainty stage 1 uses: options.gravity_sigma_mps2, else
// earth::site_gravity_sigma_mps2 (measured or normal gravity).
double gravity_sigma_mps2(const RecordingMeta& meta, const Options& options);
// The bench's type B sources of stage 1's budget (the table's and the g's), each with the largest
// 1-sigma of its parameters (ReferencePerturbation::sigma): what a bench requirement scales
// (plan::source_requirements). Empty with options.type_b false.
std::map<std::string, double> bench_source_sigmas(const RecordingMeta& meta, const Options& options);

// One accumulated interval: a static or a rest-to-rest rotation between two statics.
struct Interval : ReferenceSums {
  std::string name;
  bool is_static = false;
  double t0_s = 0, t1_s = 0;
  double T_s = 0;                       // sum of frame intervals inside
  long long frames = 0;
  Eigen::Vector3d sum_dtheta = Eigen::Vector3d::Zero(), sum_dv = Eigen::Vector3d::Zero();
  Eigen::Vector3d sumsq_dtheta = Eigen::Vector3d::Zero(), sumsq_dv = Eigen::Vector3d::Zero();
  Eigen::Vector3d moved_axes_rad = Eigen::Vector3d::Zero();  // |total angle change| per table axis
  bool gap = false;
  // The reference sums again under each of the calibrator's ReferencePerturbations, in order.
  std::vector<ReferenceSums> perturbed;
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
  // Instrument frame, with sigma, the combined standard uncertainty of each coefficient stage 1
  // estimates, and the budget behind it (ImuModel::budget): "type_a" (the fit's own, from its
  // residuals and design), each table source, "site.gravity_mps2", and "start_model.<key>" for
  // each nonlinear term taken from the start model with a sigma.
  ImuModel model;
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
  // The budget's type B references: perturbation_sources_[p] names perturbed_references_[p].
  std::vector<std::string> perturbation_sources_;
  std::vector<table_reference::FrameReference> perturbed_references_;
  double g_mps2_;
  double dt_nominal_s_;
  std::vector<Interval> intervals_;
  Interval* current_ = nullptr;
  bool have_prev_ = false;
  ImuFrame prev_;
};

// Stage 1's uncertainty budget (issue 34; ImuModel::budget), for the fit that converged to `gyro`
// and `accel` on `intervals`: the shift of each coefficient when each type B source moves by its
// standard uncertainty (the perturbed references the intervals carry, named by
// perturbation_sources; each nonlinear term of the start model with a sigma in start_sigma, which
// the designs take as known), re-solved at the same errors. `sigma` holds the fit's own (type A)
// sigma of each coefficient stage 1 estimates and is replaced by the combined standard
// uncertainty, the root-sum-square over the sources. Returns the budget: `carried` (a start
// model's) without this stage's coefficients, then "type_a" and each source for them.
std::map<std::string, ImuErrorSet> uncertainty_budget(const std::vector<Interval>& intervals, const Options& options,
                                                      const std::vector<std::string>& perturbation_sources,
                                                      const GyroErrors& gyro, const AccelErrors& accel,
                                                      const ImuErrorSet& start_sigma, ImuErrorSet& sigma,
                                                      const std::map<std::string, ImuErrorSet>& carried);

// The same model in the body frame built on the accelerometer axes (X = accel x, Y in the accel
// x-y plane): misalignments relative to b and body_to_instrument_arcsec.
ImuModel to_body_frame(const ImuModel& instrument_model);

}  // namespace imucal::direct
