#include "estimators/tumble.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <stdexcept>
#include <string>

#include "core/earth.hpp"
#include "core/units.hpp"
#include "estimators/least_squares.hpp"
#include "estimators/stage_model.hpp"
#include "estimators/table_reference.hpp"

namespace imucal::tumble {

using Eigen::MatrixXd;
using Eigen::Vector3d;
using Eigen::VectorXd;

namespace {

const char* kAxis[3] = {"x", "y", "z"};

struct Static {
  std::string name;
  double t0_s = 0, t1_s = 0;
  double T_s = 0;
  long long frames = 0;
  bool gap = false;
  Vector3d sum_dv_mps = Vector3d::Zero(), sum_dtheta_rad = Vector3d::Zero();
  Vector3d earth_rad = Vector3d::Zero();  // the Earth's rotation of o over the static
  Vector3d f_o_mps2 = Vector3d::Zero();
};

// The two misalignment angles that act on row j of D: each with its column of D - I per radian
// (from misalignment_matrix, so the sign convention is the model's own).
struct AngleColumn {
  const MisalignmentKey* key;
  Vector3d row_per_rad;  // d(D.row(j)) / d(angle)
};
std::vector<AngleColumn> angles_of_row(int j) {
  std::vector<AngleColumn> out;
  for (const MisalignmentKey& k : kMisalignmentKeys) {
    Misalignment m;
    m.*k.member = 1.0;
    const Vector3d row = (misalignment_matrix(m) - Eigen::Matrix3d::Identity()).row(j).transpose();
    if (row.cwiseAbs().maxCoeff() > 0.5) out.push_back({&k, row});
  }
  return out;
}

// The 1-sigma of each element of the prior's gyro D S - I (misalignment angles off the diagonal,
// scale factors on it, the larger of + and -): zero when the prior states none.
Eigen::Matrix3d gyro_prior_sigma(const ImuModel& prior) {
  if (!prior.sigma) return Eigen::Matrix3d::Zero();
  const GyroErrors& s = prior.sigma->gyro;
  Eigen::Matrix3d out = (misalignment_matrix(s.misalignment_rad) - Eigen::Matrix3d::Identity()).cwiseAbs();
  for (int j = 0; j < 3; ++j) out(j, j) = std::max(std::abs(s.scale_pos[j]), std::abs(s.scale_neg[j]));
  return out;
}

// The statics a fit may use: two frames or more, and none with a gap in its frames (the mean over
// a gap is not the mean over the static). The ones left out for a gap are counted for the note.
struct UsableStatics {
  std::vector<const Static*> rows;
  int left_out_for_gap = 0;
};
UsableStatics usable_statics(const std::vector<Static>& statics) {
  UsableStatics out;
  for (const Static& s : statics) {
    if (s.frames < 2) continue;
    if (s.gap) {
      ++out.left_out_for_gap;
      continue;
    }
    out.rows.push_back(&s);
  }
  return out;
}

// Each static's weight: its duration, as a mean's variance falls as 1/T.
VectorXd weights_by_duration(const std::vector<const Static*>& rows) {
  const auto n = static_cast<Eigen::Index>(rows.size());
  VectorXd w(n);
  for (Eigen::Index i = 0; i < n; ++i) w[i] = rows[static_cast<std::size_t>(i)]->T_s;
  return w;
}

// Accelerometer j's least squares: its terms (x: bias, scale, K2, K3, then the angles of `angles`
// in their order) and its residual at each static, m/s^2.
struct AccelRowFit {
  std::vector<AngleColumn> angles;
  least_squares::Fit fit;
  VectorXd residual_mps2;
};
// Throws, naming `what` the statics leave undetermined and the program that determines it, when
// the fit's columns are (nearly) dependent.
void require_determined(const MatrixXd& A, const VectorXd& w, const std::string& what) {
  if (least_squares::min_scaled_eigenvalue(A, w) < 1e-10)
    throw std::runtime_error("tumble: the statics do not determine " + what + ": run the tumble or tumble-short program)");
}

AccelRowFit fit_accelerometer_row(int j, const std::vector<const Static*>& rows, const VectorXd& w) {
  constexpr double g = units::kStandardGravity_mps2;
  const auto n = static_cast<Eigen::Index>(rows.size());
  // Accelerometer j's mean output against the reference specific force.
  AccelRowFit out;
  out.angles = angles_of_row(j);
  const std::vector<AngleColumn>& angles = out.angles;
  MatrixXd A(n, 4 + static_cast<Eigen::Index>(angles.size()));
  VectorXd b(n);
  for (Eigen::Index i = 0; i < n; ++i) {
    const Static& s = *rows[static_cast<std::size_t>(i)];
    const double fj = s.f_o_mps2[j];
    A(i, 0) = 1.0;                  // bias
    A(i, 1) = fj;                   // scale
    A(i, 2) = fj * fj / g;          // K2: the scale error gains k2 a, a = f_j / g
    A(i, 3) = fj * fj * fj / (g * g);  // K3: the scale error gains k3 a^2
    for (std::size_t c = 0; c < angles.size(); ++c) A(i, 4 + static_cast<Eigen::Index>(c)) = angles[c].row_per_rad.dot(s.f_o_mps2);
    b[i] = s.sum_dv_mps[j] / s.T_s - fj;
  }
  require_determined(A, w, std::string("accelerometer ") + kAxis[j] +
                               "'s bias, scale, K2, K3 and angles (it must turn through a whole vertical circle");
  out.fit = least_squares::solve(A, b, w);
  out.residual_mps2 = b - A * out.fit.x;
  return out;
}

// Accelerometer j's terms and sigmas into the model, its residuals into the positions.
void store_accelerometer_row(int j, const AccelRowFit& row, Result& out, ImuErrorSet& sigma) {
  const least_squares::Fit& fit = row.fit;
  AccelErrors& a = out.model.accel;
  a.bias_mps2[j] = fit.x[0];
  a.scale[j] = fit.x[1];
  a.k2_per_g[j] = fit.x[2];
  a.k3_per_g2[j] = fit.x[3];
  sigma.accel.bias_mps2[j] = std::sqrt(fit.covariance(0, 0));
  sigma.accel.scale[j] = std::sqrt(fit.covariance(1, 1));
  sigma.accel.k2_per_g[j] = std::sqrt(fit.covariance(2, 2));
  sigma.accel.k3_per_g2[j] = std::sqrt(fit.covariance(3, 3));
  for (std::size_t c = 0; c < row.angles.size(); ++c) {
    const auto k = static_cast<Eigen::Index>(4 + c);
    a.misalignment_rad.*(row.angles[c].key->member) = fit.x[k];
    sigma.accel.misalignment_rad.*(row.angles[c].key->member) = std::sqrt(fit.covariance(k, k));
  }
  const VectorXd& r = row.residual_mps2;
  const auto n = r.size();
  for (Eigen::Index i = 0; i < n; ++i) out.positions[static_cast<std::size_t>(i)].accel_residual_mps2[j] = r[i];
  out.accel_residual_rms_mps2[j] = std::sqrt(r.squaredNorm() / static_cast<double>(n));
}

// The prior's gyro scale factors and misalignments alone: what takes the Earth rate out of each
// gyro's mean at rest (its bias and g-sensitivity are what the tumble fits).
GyroErrors earth_rate_model(const ImuModel& prior) {
  GyroErrors earth_model = prior.gyro;
  earth_model.bias_radps.setZero();
  earth_model.g_sensitivity_radps_per_g.setZero();
  return earth_model;
}

// The Earth rate's vertical part turns with the specific force through the whole tumble (both are
// fixed in the local level frame), so an error in the prior's D S (the gyros' misalignments and
// scale factors that take the Earth rate out) is exactly a g-sensitivity: element (j, k) of D S
// off by e puts e times the vertical Earth rate into g-sensitivity (j, k), per g. Its sigma
// carries the prior's uncertainty so; a prior without gyro terms or sigma is said to confound
// them.
bool gyro_terms_confounded(const ImuModel& prior) {
  return !prior.sigma && prior.gyro.scale_pos.isZero(0.0) && prior.gyro.scale_neg.isZero(0.0) &&
         (misalignment_matrix(prior.gyro.misalignment_rad) - Eigen::Matrix3d::Identity()).isZero(0.0);
}
std::string confounded_gyro_note(double earth_vertical_radps) {
  char confounded[400];
  std::snprintf(confounded, sizeof confounded,
                "tumble: no stage-1 model given: the gyro g-sensitivity holds the gyros' misalignments and scale "
                "errors times the vertical Earth rate (%.2f deg/h here: every 10 arcsec of misalignment is %.5f "
                "deg/h/g), which its sigma does not include; give the tumble a stage-1 start model",
                earth_vertical_radps * units::kRadpsToDph,
                10.0 * units::kArcsecToRad * earth_vertical_radps * units::kRadpsToDph);
  return confounded;
}

// Gyro j's least squares at rest: what it measured beyond the Earth rate (through the prior's
// scale factors and misalignments, `earth_model`) against the specific force at its origin, in g.
// x: bias, then the g-sensitivity row; the residual at each static in rad/s.
struct GyroRowFit {
  least_squares::Fit fit;
  VectorXd residual_radps;
};
GyroRowFit fit_gyro_row(int j, const std::vector<const Static*>& rows, const VectorXd& w, const GyroErrors& earth_model) {
  constexpr double g = units::kStandardGravity_mps2;
  const auto n = static_cast<Eigen::Index>(rows.size());
  MatrixXd A(n, 4);
  VectorXd b(n);
  for (Eigen::Index i = 0; i < n; ++i) {
    const Static& s = *rows[static_cast<std::size_t>(i)];
    A(i, 0) = 1.0;
    A.block(i, 1, 1, 3) = s.f_o_mps2.transpose() / g;
    const Vector3d earth_out = apply_gyro_scale_misalignment(earth_model, s.earth_rad / s.T_s);
    b[i] = s.sum_dtheta_rad[j] / s.T_s - earth_out[j];
  }
  require_determined(A, w, std::string("gyro ") + kAxis[j] +
                               "'s g-sensitivity (the specific force must point along every axis of the IMU");
  GyroRowFit out;
  out.fit = least_squares::solve(A, b, w);
  out.residual_radps = b - A * out.fit.x;
  return out;
}

// Gyro j's bias and g-sensitivity row with their sigmas into the model, its residuals into the
// positions.
void store_gyro_row(int j, const GyroRowFit& row, const Eigen::Matrix3d& prior_DS_sigma, double earth_vertical_radps,
                    Result& out, ImuErrorSet& sigma) {
  const least_squares::Fit& fit = row.fit;
  out.model.gyro.bias_radps[j] = fit.x[0];
  sigma.gyro.bias_radps[j] = std::sqrt(fit.covariance(0, 0));
  for (int k = 0; k < 3; ++k) {
    out.model.gyro.g_sensitivity_radps_per_g(j, k) = fit.x[1 + k];
    // Type B: the prior's uncertainty in element (j, k) of D S moves this term by as much times
    // the Earth rate's vertical component (see gyro_prior_sigma).
    const double prior_part = prior_DS_sigma(j, k) * earth_vertical_radps;
    sigma.gyro.g_sensitivity_radps_per_g(j, k) = std::sqrt(fit.covariance(1 + k, 1 + k) + prior_part * prior_part);
  }
  const VectorXd& r = row.residual_radps;
  const auto n = r.size();
  for (Eigen::Index i = 0; i < n; ++i) out.positions[static_cast<std::size_t>(i)].gyro_residual_radps[j] = r[i];
  out.gyro_residual_rms_radps[j] = std::sqrt(r.squaredNorm() / static_cast<double>(n));
}

// What each position was: its static, its duration, the reference and the accelerometers' mean.
void describe_positions(const std::vector<const Static*>& rows, std::vector<Position>& positions) {
  for (std::size_t i = 0; i < rows.size(); ++i) {
    const Static& s = *rows[i];
    Position& p = positions[i];
    p.segment = s.name;
    p.duration_s = s.T_s;
    p.f_o_mps2 = s.f_o_mps2;
    p.accel_mps2 = s.sum_dv_mps / s.T_s;
  }
}

std::string summary_note(const Result& r, Eigen::Index statics) {
  constexpr double g = units::kStandardGravity_mps2;
  char buf[256];
  std::snprintf(buf, sizeof buf,
                "tumble: %lld statics; accelerometer residual rms %.2f %.2f %.2f ug, gyro %.4f %.4f %.4f deg/h",
                static_cast<long long>(statics), r.accel_residual_rms_mps2[0] / g * 1e6, r.accel_residual_rms_mps2[1] / g * 1e6,
                r.accel_residual_rms_mps2[2] / g * 1e6, r.gyro_residual_rms_radps[0] * units::kRadpsToDph,
                r.gyro_residual_rms_radps[1] * units::kRadpsToDph, r.gyro_residual_rms_radps[2] * units::kRadpsToDph);
  return buf;
}

}  // namespace

struct TumbleEstimator::Impl {
  table_reference::FrameReference reference;
  std::vector<Static> statics;
  table_reference::SegmentFrames frames{{}};
  double dt_nominal_s;
  double earth_vertical_radps;  // the Earth rate's component along the local vertical
  table_reference::FrameIntervals intervals;

  explicit Impl(const RecordingMeta& m)
      : reference(m),
        dt_nominal_s(1.0 / m.rate_hz),
        earth_vertical_radps(earth::kOmega_radps * std::sin(m.site.latitude_deg * units::kDegToRad)) {
    for (const SegmentInfo& s : m.segments)
      if (s.kind == "static" || s.kind == "tilt") statics.push_back({s.name, s.t0_s, s.t1_s});
    std::sort(statics.begin(), statics.end(), [](const Static& a, const Static& b) { return a.t0_s < b.t0_s; });
    std::vector<table_reference::SegmentFrames::Span> spans;
    for (const Static& s : statics) spans.push_back({s.t0_s, s.t1_s, false});
    frames = table_reference::SegmentFrames(std::move(spans));
  }

  void push(const ImuFrame& f) {
    const auto iv = intervals.next(f);
    if (!iv) return;
    const double dt = iv->dt_s;
    const ImuFrame& prev = iv->prev;
    // The frames wholly inside a static: the table is at rest over each of them.
    if (const int i = frames.assign(iv->t_prev_s, iv->t_s); i >= 0) {
      Static& s = statics[static_cast<std::size_t>(i)];
      if (dt > 1.5 * dt_nominal_s || dt <= 0) s.gap = true;
      if (s.frames == 0) s.f_o_mps2 = reference.specific_force_at_rest_o_mps2(f.table_deg);
      s.earth_rad += reference.increment_o_rad(prev.table_deg, f.table_deg, dt);
      s.sum_dv_mps += f.dv_mps;
      s.sum_dtheta_rad += f.dtheta_rad;
      s.T_s += dt;
      ++s.frames;
    }
  }
};

TumbleEstimator::TumbleEstimator(const RecordingMeta& meta) : impl_(std::make_unique<Impl>(meta)) {}
TumbleEstimator::~TumbleEstimator() = default;
void TumbleEstimator::push(const ImuFrame& frame) { impl_->push(frame); }
int TumbleEstimator::statics_seen() const {
  return static_cast<int>(std::count_if(impl_->statics.begin(), impl_->statics.end(), [](const Static& s) { return s.frames >= 2; }));
}

Result TumbleEstimator::finish(const ImuModel& prior) const {
  Result out;
  out.model = stage_model_from(prior);
  ImuErrorSet& sigma = sigma_to_fill(out.model);

  const UsableStatics usable = usable_statics(impl_->statics);
  if (usable.left_out_for_gap)
    out.notes.push_back(std::to_string(usable.left_out_for_gap) + " static(s) left out: a gap in the frames");
  const std::vector<const Static*>& rows = usable.rows;
  const auto n = static_cast<Eigen::Index>(rows.size());
  // Each accelerometer: bias, scale, K2, K3, two angles. Each gyro: bias and a g-sensitivity row.
  if (n < 12)
    throw std::runtime_error("tumble: " + std::to_string(n) +
                             " statics; the tumble needs 12 at least, at many angles of a whole turn in two vertical "
                             "planes (run the tumble or tumble-short program)");
  out.positions.resize(static_cast<std::size_t>(n));
  const VectorXd w = weights_by_duration(rows);

  for (int j = 0; j < 3; ++j) store_accelerometer_row(j, fit_accelerometer_row(j, rows, w), out, sigma);

  if (gyro_terms_confounded(prior))
    out.notes.push_back(confounded_gyro_note(impl_->earth_vertical_radps));
  const GyroErrors earth_model = earth_rate_model(prior);
  const Eigen::Matrix3d prior_DS_sigma = gyro_prior_sigma(prior);
  for (int j = 0; j < 3; ++j)
    store_gyro_row(j, fit_gyro_row(j, rows, w, earth_model), prior_DS_sigma, impl_->earth_vertical_radps, out, sigma);

  describe_positions(rows, out.positions);
  out.notes.push_back(summary_note(out, n));
  return out;
}

}  // namespace imucal::tumble
