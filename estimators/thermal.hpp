// Stage 2 of the method (seed ch. 3): temperature models of every coefficient of the sensor model.
//  - The model's "thermal" section (schema in docs/thermal.md): per coefficient, polynomials in
//    the temperature of the sensor it belongs to (centred on T_ref) and in that temperature's rate
//    of change, added to the model's own value (seed eq. 8; see the header of thermal.cpp for why
//    additive everywhere), and the compensation that evaluates them.
//  - Per-cycle estimates: one stage-1 DirectCalibrator per table cycle, and the temperature each
//    estimate refers to (the calibrator's own weighting of the intervals applied to the
//    temperatures, so that a drift inside a cycle does not bias the fit).
//  - Checks of the temperature channels (stuck, missing, jumping, chamber short of its set point),
//    the eq. 8 fits by least squares with the degrees chosen by held-back cycles, and the report.
// Pure: samples in, results out; no clock, no I/O.
#pragma once

#include <array>
#include <deque>
#include <limits>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "core/imu_model.hpp"
#include "core/recording.hpp"
#include "estimators/direct_calibration.hpp"

namespace imucal::thermal {

// ------------------------------------------------------------------------------------------------
// Coefficients and temperature channels

inline constexpr int kCoefficients = 27;  // gyro: 3 bias, 3+3 scale (+/-), 6 angles; accel: 3, 3, 6
inline constexpr int kChannels = 6;       // FOG coil means x y z, accelerometers x y z

struct Coefficient {
  int index = 0;
  const char* group = "";   // report key, e.g. "gyro.bias_dph"
  const char* member = "";  // "x" or a misalignment "xy"
  bool gyro = true;
  int sensor_axis = 0;      // j: the sensor whose temperature drives it (row j of D for an angle)
  double si_to_json = 1.0;  // SI value * si_to_json = value in the JSON unit of the group
};
const std::array<Coefficient, kCoefficients>& coefficients();
std::string full_key(const Coefficient& c);          // "gyro.bias_dph.x"
inline int channel_of(const Coefficient& c) { return (c.gyro ? 0 : 3) + c.sensor_axis; }
const char* channel_name(int channel);               // "temp_gx_C" .. "temp_az_C"
// The report groups of the issue, in order; every coefficient belongs to one.
const std::array<const char*, 7>& groups();

// Value of coefficient c in its JSON unit, and setting it from one.
double get(const GyroErrors& g, const AccelErrors& a, const Coefficient& c);
void set(GyroErrors& g, AccelErrors& a, const Coefficient& c, double json_value);

// Temperatures of the six channels and their rates (C/min), as the compensation uses them.
struct ChannelTemps {
  Eigen::Matrix<double, kChannels, 1> T_C = Eigen::Matrix<double, kChannels, 1>::Constant(25.0);
  Eigen::Matrix<double, kChannels, 1> rate_C_per_min = Eigen::Matrix<double, kChannels, 1>::Zero();
};

// ------------------------------------------------------------------------------------------------
// The "thermal" section

// Sum over n >= 1 of T[n-1] (T - T_ref)^n + dTdt[n-1] rate^n, in the coefficient's JSON unit,
// T in C, rate in C/min. Empty lists: no dependence.
struct Poly {
  std::vector<double> T;
  std::vector<double> dTdt;
  double eval(double dT_C, double rate_C_per_min) const;
  bool empty() const { return T.empty() && dTdt.empty(); }
};

// Truth files only: the FOG bias oscillation the polynomials cannot describe (seed: light-source
// power control while the temperature changes). Amplitude scales from 0 at |rate| = onset to
// full at |rate| = full (smoothstep in between); the phase of gyro j is phase_deg[j].
struct Oscillation {
  double amplitude_dph = 0.0;
  double period_s = 1200.0;
  double onset_C_per_min = 0.05;
  double full_C_per_min = 0.15;
  std::array<double, 3> phase_deg = {0.0, 120.0, 240.0};
};
double oscillation_dph(const Oscillation& o, int axis, double t_s, double rate_C_per_min);

struct ThermalSection {
  double T_ref_C = 25.0;
  std::array<Poly, kCoefficients> poly;
  // The data the fit saw (for the operator: outside it the polynomials extrapolate).
  std::optional<std::array<double, 2>> fitted_T_C, fitted_rate_C_per_min;
  std::optional<Oscillation> sim_oscillation;  // truth files only

  bool has_models() const;
};

// Parses the section (JSON text of the "thermal" value). Throws std::runtime_error naming the key.
ThermalSection parse_thermal(const std::string& json_text, const std::string& where);
std::string thermal_to_json_text(const ThermalSection& s);
// The model's section, or nothing when it has none.
std::optional<ThermalSection> thermal_of(const ImuModel& m);

// Adds the polynomials at these temperatures to the coefficients (which hold the values at
// T_ref and zero rate). Delays, lever arms and noise are untouched.
void apply_thermal(const ThermalSection& s, const ChannelTemps& temps, GyroErrors& g, AccelErrors& a);

// Temperatures and rates for compensation while the run goes on: the rate is the slope of a
// least-squares line over the trailing window (causal, so the daemon can use it too).
class ChannelRate {
 public:
  explicit ChannelRate(double window_s = 120.0) : window_s_(window_s) {}
  void push(const TempSample& s);
  bool ready() const { return !samples_.empty(); }
  ChannelTemps current() const;

 private:
  struct Entry {
    double t_s;
    Eigen::Matrix<double, kChannels, 1> T_C;
  };
  double window_s_;
  std::deque<Entry> samples_;
};

// ------------------------------------------------------------------------------------------------
// Least-squares fits of eq. 8 with the degree chosen by held-back cycles

struct Sample {
  double T_C = 0, rate_C_per_min = 0;
  double value = 0;  // JSON unit
};

struct DegreeScore {
  int T_degree = 0, rate_degree = 0;
  double fit_rms = 0;  // residual RMS of the fit to all cycles
  double cv_rms = 0;   // RMS of the residuals of held-back cycles, each predicted without it
};

struct FitOptions {
  int max_T_degree = 4;
  int max_rate_degree = 3;
  int folds = 5;                 // held-back cycles: every folds-th cycle in turn
  double min_samples_per_parameter = 3.0;
  // A simpler model is kept unless the best one predicts held-back cycles better, in mean square,
  // by more than standard_errors standard errors of the paired difference, by more than
  // min_improvement of its own mean square, and by more than resolution^2 (JSON unit): an
  // improvement within the scatter of the estimates, or too small to matter, never buys a degree.
  double standard_errors = 2.0;
  double min_improvement = 0.0;
  double resolution = 0.0;
};

struct PolyFit {
  Poly poly;
  double constant = 0, constant_sigma = 0;  // value at T_ref and zero rate
  int T_degree = 0, rate_degree = 0;
  double fit_rms = 0, cv_rms = 0;
  int samples = 0;
  std::vector<DegreeScore> scores;
};

// Throws std::runtime_error when there are too few samples for even a constant.
PolyFit fit_polynomial(const std::vector<Sample>& samples, double T_ref_C, const FitOptions& options);

// ------------------------------------------------------------------------------------------------
// Per-cycle estimates

// One table cycle: its statics and the next cycle's first one (the rest that closes the cycle's
// last rotation).
struct Cycle {
  std::string name;
  std::vector<SegmentInfo> statics;
  double t0_s = 0, t1_s = 0;
};

// Groups the run's statics into cycles: by the "cycle-NNN/" prefix of the segment names (the
// built-in programs), else every statics_per_cycle statics. Throws when neither applies.
std::vector<Cycle> find_cycles(const std::vector<SegmentInfo>& segments, int statics_per_cycle = 0);

struct CycleEstimate {
  std::string name;
  double t0_s = 0, t1_s = 0;
  bool ok = false;
  std::string note;  // why there is no estimate
  std::array<double, kCoefficients> value{}, sigma{};  // JSON units
  // The intervals the calibrator used and, per coefficient, how much each contributed to the
  // estimate (the row of (A'WA)^-1 A'W times the column of A: they sum to one).
  std::vector<std::array<double, 2>> spans;
  std::array<std::vector<double>, kCoefficients> weight;
  // The stage-1 least squares of each sensor (gyro x y z, accel x y z) at the solution: its
  // coefficients, the intervals (into spans) and K = (A'WA)^-1 A'W, to tell how much of one
  // coefficient's change inside the cycle leaks into another's estimate.
  struct Design {
    std::vector<int> coefficient;  // indices into coefficients()
    std::vector<std::size_t> interval;
    Eigen::MatrixXd A, K;
  };
  std::array<Design, 6> design;
  // |K b - estimate| per coefficient (JSON unit), b the cycle's own measurements: zero when the
  // design above is stage 1's; a check that it still is.
  std::array<double, kCoefficients> design_mismatch{};
};

// Runs one DirectCalibrator per cycle over a single pass of the frames.
class CycleEstimator {
 public:
  CycleEstimator(const RecordingMeta& meta, std::vector<Cycle> cycles, const ImuModel& seed);
  void push(const ImuFrame& frame);
  std::vector<CycleEstimate> finish();

 private:
  struct Active {
    std::size_t index;
    std::unique_ptr<direct::DirectCalibrator> calibrator;
  };
  void close(Active& a);
  RecordingMeta meta_;
  std::vector<Cycle> cycles_;
  ImuModel seed_;
  std::vector<Active> active_;
  std::vector<CycleEstimate> results_;
  std::size_t next_open_ = 0;
};

// ------------------------------------------------------------------------------------------------
// Temperature checks

struct TempProblem {
  std::string channel;  // temp_gx_C .. temp_az_C, temp_chamber_C, "all"
  std::string what;
  double t0_s = 0, t1_s = 0;
  unsigned channel_mask = 0;  // bit ch: coefficients on channel ch are affected
};

struct CheckOptions {
  double stuck_s = 600.0;               // unchanged this long while the median of the sensors of
  double stuck_others_change_C = 0.05;  // like time constant moved by this much: stuck, unless
  double air_still_C = 0.5;             // the chamber air moved less than this (a soak: settled)
  double jump_C = 0.3;                 // a step larger than this plus the physical rate: a jump
  double max_rate_C_per_min = 5.0;
  double gap_s = 30.0;                 // no samples this long while the values moved: missing
  double plausible_lo_C = -60.0, plausible_hi_C = 150.0;
  double setpoint_tolerance_C = 0.5;   // chamber air at the end of a soak
  double setpoint_settle_s = 900.0;    // soaks shorter than this are not judged
};

std::vector<TempProblem> check_temperatures(const std::vector<TempSample>& temps, const CheckOptions& options);

// ------------------------------------------------------------------------------------------------
// The whole stage

struct Options {
  FitOptions fit;
  CheckOptions checks;
  double T_ref_C = std::numeric_limits<double>::quiet_NaN();  // NaN: the middle of the data
  double range_lo_C = 15.0, range_hi_C = 35.0;  // the range the run was asked to cover
  double coverage_tolerance_C = 1.0;
  double rate_half_window_s = 120.0;  // centred window for the rate of each interval
  int leak_iterations = 2;             // rounds of removing what one coefficient leaks into another
  // Per report group (groups() order): the smallest RMS a term must explain to be fitted, a tenth
  // of the seed's figures after compensation (accel 1e-5 m/s^2, 10 ppm, 3"; FOG 0.01 deg/h,
  // 20 ppm, 2"): below that a term does not matter, and in noise-free data nothing else would stop
  // a degree from fitting the last traces of the cycles' own averaging.
  std::array<double, 7> resolution = {1e-6, 1.0, 0.3, 2e-4, 2.0, 2.0, 0.2};
};

struct Result {
  ImuModel model;  // the input with the constants at T_ref replaced and the thermal section set
  ThermalSection section;
  std::vector<std::string> notes;     // problems and left-out cycles, by name and time
  std::vector<TempProblem> problems;
  int cycles_total = 0, cycles_used = 0;
  std::string report_json;  // imucal-thermal-report/1 (docs/thermal.md)
};

// `input` is the stage-1 model (its constants are "before"). A simulated run (meta.truth_json set)
// is judged against its truth; a real one against its own per-cycle estimates.
Result calibrate(const RecordingMeta& meta, const std::vector<CycleEstimate>& cycles,
                 const std::vector<TempSample>& temps, const ImuModel& input, const Options& options);
// The same checks and report for a model fitted before (e.g. over 15..35 C, judged on a run with
// the IMU's thermal stabilisation): nothing is fitted; "before" is the model without its section.
Result evaluate(const RecordingMeta& meta, const std::vector<CycleEstimate>& cycles,
                const std::vector<TempSample>& temps, const ImuModel& model, const Options& options);
// Keeps the model's polynomials (their shape, from a run that covered the range) and fits only
// the constants at T_ref to this run: a later run, e.g. with the IMU's thermal stabilisation,
// whose narrow range cannot determine a shape but pins the level to a fraction of the noise.
Result refit_constants(const RecordingMeta& meta, const std::vector<CycleEstimate>& cycles,
                       const std::vector<TempSample>& temps, const ImuModel& model, const Options& options);

}  // namespace imucal::thermal
