#include "estimators/rate_steps.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <stdexcept>

#include <Eigen/Dense>

#include "core/units.hpp"
#include "estimators/held_back.hpp"
#include "estimators/least_squares.hpp"
#include "estimators/rate_moments.hpp"
#include "estimators/stage_model.hpp"
#include "estimators/table_reference.hpp"

namespace imucal::rate_steps {

using Eigen::MatrixXd;
using Eigen::Vector3d;
using Eigen::VectorXd;
using units::kDegToRad;
using units::kRadToDeg;

namespace {

const char* kAxis[3] = {"x", "y", "z"};

// One segment of the recording, accumulated: a static, or a rate segment (rest to rest).
struct Segment {
  std::string name;
  bool is_static = false;
  double t0_s = 0, t1_s = 0;
  double T_s = 0;
  long long frames = 0;
  bool gap = false;
  Vector3d sum_dtheta_rad = Vector3d::Zero();
  Vector3d ref_pos_rad = Vector3d::Zero(), ref_neg_rad = Vector3d::Zero();  // reference, split by sign
  // The nonlinear terms' regressors: integral of w_j (|w_j| / 100 deg/s)^k dt, k = 1..3.
  std::array<Vector3d, 3> moment_rad{Vector3d::Zero(), Vector3d::Zero(), Vector3d::Zero()};
  double peak_table_rate_dps = 0;               // the fastest table axis's largest rate (the cruise)
  Vector3d f_o_mps2 = Vector3d::Zero();         // specific force at rest at its first frame
  Vector3d ref_rad() const { return ref_pos_rad + ref_neg_rad; }
};

// Row of the design for gyro j: bias (times T), scale +, scale -, then c1 .. c_degree.
VectorXd design_row(const Segment& s, int j, int degree) {
  VectorXd r(3 + degree);
  r[0] = s.T_s;
  r[1] = s.ref_pos_rad[j];
  r[2] = s.ref_neg_rad[j];
  for (int k = 0; k < degree; ++k) r[3 + k] = s.moment_rad[static_cast<std::size_t>(k)][j];
  return r;
}

struct Solved {
  bool ok = false;
  least_squares::Fit fit;
};

// The fit of gyro j's rows (those `use` keeps) at a degree; not ok when the rows do not determine it.
Solved solve(const std::vector<const Segment*>& rows, const std::vector<double>& y, int j, int degree,
             const std::vector<bool>* use = nullptr) {
  std::vector<std::size_t> kept;
  for (std::size_t i = 0; i < rows.size(); ++i)
    if (!use || (*use)[i]) kept.push_back(i);
  const auto n = static_cast<Eigen::Index>(kept.size());
  MatrixXd A(n, 3 + degree);
  VectorXd b(n), w(n);
  for (Eigen::Index r = 0; r < n; ++r) {
    const std::size_t i = kept[static_cast<std::size_t>(r)];
    A.row(r) = design_row(*rows[i], j, degree).transpose();
    b[r] = y[i];
    w[r] = 1.0 / rows[i]->T_s;  // white angle noise: the variance grows with the time
  }
  Solved s;
  if (n < A.cols() || least_squares::min_scaled_eigenvalue(A, w) < 1e-10) return s;
  s.fit = least_squares::solve(A, b, w);
  s.ok = s.fit.x.allFinite();
  return s;
}

// The ladder's rates: steps whose cruise rates agree within 1 % are one rate (both directions, and
// the few tenths of a percent a real table's encoder rate scatters).
std::vector<int> group_rates(const std::vector<double>& rates_dps) {
  std::vector<std::size_t> order(rates_dps.size());
  for (std::size_t i = 0; i < order.size(); ++i) order[i] = i;
  std::sort(order.begin(), order.end(), [&](std::size_t a, std::size_t b) { return rates_dps[a] < rates_dps[b]; });
  std::vector<int> group(rates_dps.size(), 0);
  int g = -1;
  double first = 0;
  for (std::size_t i : order) {
    if (g < 0 || rates_dps[i] > 1.01 * first) {
      ++g;
      first = rates_dps[i];
    }
    group[i] = g;
  }
  return group;
}

}  // namespace

double Axis::scale_ppm_at(double rate_dps, double* sigma_ppm) const {
  const auto p = covariance_ppm2.rows();
  VectorXd g = VectorXd::Zero(p);
  if (p >= 2) g[rate_dps >= 0 ? 0 : 1] = 1.0;
  const double q = std::abs(rate_dps) / (kGyroNonlinearityRate_radps * kRadToDeg);
  double value = rate_dps >= 0 ? scale_pos_ppm : scale_neg_ppm;
  for (int k = 0; k < degree; ++k) {
    const double qk = std::pow(q, k + 1);
    value += nonlinear_ppm[static_cast<std::size_t>(k)] * qk;
    if (2 + k < p) g[2 + k] = qk;
  }
  if (sigma_ppm) *sigma_ppm = p > 0 ? std::sqrt(std::max(0.0, g.dot(covariance_ppm2 * g))) : 0.0;
  return value;
}

struct RateStepsEstimator::Impl {
  Options options;
  table_reference::FrameReference reference;
  std::vector<Segment> segments;  // statics and rate segments, by time
  table_reference::SegmentFrames frames{{}};
  double dt_nominal_s = 0;
  table_reference::FrameIntervals intervals;

  Impl(const RecordingMeta& m, const Options& o) : options(o), reference(m), dt_nominal_s(1.0 / m.rate_hz) {
    for (const SegmentInfo& s : m.segments) {
      if (s.kind != "static" && s.kind != "rate") continue;
      Segment seg;
      seg.name = s.name;
      seg.is_static = s.kind == "static";
      seg.t0_s = s.t0_s;
      seg.t1_s = s.t1_s;
      segments.push_back(seg);
    }
    std::sort(segments.begin(), segments.end(), [](const Segment& a, const Segment& b) { return a.t0_s < b.t0_s; });
    std::vector<table_reference::SegmentFrames::Span> spans;
    for (const Segment& s : segments) spans.push_back({s.t0_s, s.t1_s, !s.is_static});
    frames = table_reference::SegmentFrames(std::move(spans));
  }

  void push(const ImuFrame& f) {
    const auto iv = intervals.next(f);
    if (!iv) return;
    // Every frame, so that each knows the table's acceleration from the one before.
    const Vector3d wdt = reference.next_increment_o_rad(iv->prev.table_deg, f.table_deg, iv->dt_s);
    const int i = frames.assign(iv->t_prev_s, iv->t_s);
    if (i >= 0) accumulate(segments[static_cast<std::size_t>(i)], iv->prev, f, iv->dt_s, wdt);
  }

  void accumulate(Segment& s, const ImuFrame& prev, const ImuFrame& f, double dt, const Vector3d& wdt) {
    if (dt > 1.5 * dt_nominal_s || dt <= 0) s.gap = true;
    if (s.frames == 0) s.f_o_mps2 = reference.specific_force_at_rest_o_mps2(prev.table_deg);
    for (int k = 0; k < 3; ++k) (wdt[k] >= 0 ? s.ref_pos_rad[k] : s.ref_neg_rad[k]) += wdt[k];
    const Eigen::Matrix3d moments = rate_moments::of(wdt, dt);
    for (std::size_t m = 0; m < 3; ++m) s.moment_rad[m] += moments.col(static_cast<Eigen::Index>(m));
    if (dt > 0) s.peak_table_rate_dps = std::max(s.peak_table_rate_dps, (f.table_deg - prev.table_deg).cwiseAbs().maxCoeff() / dt);
    s.sum_dtheta_rad += f.dtheta_rad;
    s.T_s += dt;
    ++s.frames;
  }
};

RateStepsEstimator::RateStepsEstimator(const RecordingMeta& meta, const Options& options)
    : impl_(std::make_unique<Impl>(meta, options)) {}
RateStepsEstimator::~RateStepsEstimator() = default;
void RateStepsEstimator::push(const ImuFrame& frame) { impl_->push(frame); }

namespace {

// The ladder: each gyro's steps (rate segments about its axis alone, whole, without gaps, turning
// min_rotation_deg at least) and the statics without gaps, by time; why each other rate segment
// was left out.
struct Ladder {
  std::array<std::vector<const Segment*>, 3> steps_of;
  std::vector<const Segment*> statics;
  std::vector<std::string> notes;
};
Ladder select_ladder(const std::vector<Segment>& segments, double min_rotation_deg) {
  Ladder out;
  char buf[256];
  for (const Segment& s : segments) {
    if (s.frames < 2) continue;
    if (s.is_static) {
      if (!s.gap) out.statics.push_back(&s);
      continue;
    }
    const Vector3d ref = s.ref_rad();
    int j = 0;
    ref.cwiseAbs().maxCoeff(&j);
    if (s.gap) {
      out.notes.push_back("step '" + s.name + "' left out: a gap in the frames (never integrated across)");
    } else if (std::abs(ref[j]) < min_rotation_deg * kDegToRad) {
      std::snprintf(buf, sizeof buf, "step '%s' left out: it turned %.1f deg (a step needs %.0f)", s.name.c_str(),
                    std::abs(ref[j]) * kRadToDeg, min_rotation_deg);
      out.notes.push_back(buf);
    } else if ((ref - ref[j] * Vector3d::Unit(j)).norm() > 0.01 * std::abs(ref[j])) {
      out.notes.push_back("step '" + s.name + "' left out: not a rotation about one gyro axis");
    } else {
      out.steps_of[static_cast<std::size_t>(j)].push_back(&s);
    }
  }
  return out;
}

// The statics in the orientation of a gyro's steps (specific force within 1 deg of one step's):
// they give its bias there, g-sensitivity included.
std::vector<const Segment*> statics_in_orientation(const std::vector<const Segment*>& statics,
                                                   const std::vector<const Segment*>& steps) {
  std::vector<const Segment*> rows;
  for (const Segment* st : statics)
    for (const Segment* s : steps)
      if (st->f_o_mps2.normalized().dot(s->f_o_mps2.normalized()) > std::cos(1.0 * kDegToRad)) {
        rows.push_back(st);
        break;
      }
  return rows;
}

// What gyro j measured over each row beyond the reference and the prior's cross-axis terms (row j
// of its D), rad.
std::vector<double> beyond_reference_rad(const std::vector<const Segment*>& rows, int j, const Eigen::Matrix3d& D) {
  std::vector<double> y;
  for (const Segment* s : rows) {
    const Vector3d ref = s->ref_rad();
    y.push_back(s->sum_dtheta_rad[j] - D.row(j).dot(ref));
  }
  return y;
}

// Degree: every rate inside the ladder predicted (both directions) by the fit to the others.
// The ladder's ends are never held back: predicting beyond the rates a fit has seen is
// extrapolation, which every degree does badly and which would let one rate decide.
// scores[d] and rms_ppm[d]: degree d, from 0 up to the first the rates cannot determine. The rows
// are the n_statics statics, then the steps, whose rates `rate_of_step` numbers.
struct DegreeScores {
  std::vector<held_back::Score> scores;
  std::vector<DegreeScore> rms_ppm;
};
DegreeScores held_back_scores(const std::vector<const Segment*>& rows, const std::vector<double>& y, int j,
                              std::size_t n_statics, const std::vector<int>& rate_of_step, int n_rates, int max_degree) {
  DegreeScores out;
  std::vector<int> rate_of_row(rows.size(), -1);
  for (std::size_t i = n_statics; i < rows.size(); ++i) rate_of_row[i] = rate_of_step[i - n_statics];
  for (int d = 0; d <= max_degree; ++d) {
    if (n_rates < d + 2) break;
    held_back::Score sc;
    sc.params = 3 + d;
    double ss_ppm = 0;
    int held_steps = 0;
    bool ok = true;
    for (int rate = 1; rate + 1 < n_rates; ++rate) {
      std::vector<bool> use(rows.size(), true);
      for (std::size_t i = n_statics; i < rows.size(); ++i) use[i] = rate_of_row[i] != rate;
      const Solved part = solve(rows, y, j, d, &use);
      if (!part.ok) {
        ok = false;
        break;
      }
      // One sample per rate: its two directions share the nonlinear part of the error and are
      // no two independent samples of it.
      double e2 = 0;
      for (std::size_t i = n_statics; i < rows.size(); ++i) {
        if (use[i]) continue;
        const double r = y[i] - design_row(*rows[i], j, d).dot(part.fit.x);
        e2 += r * r / rows[i]->T_s;
        const double r_ppm = r / rows[i]->ref_rad()[j] * 1e6;
        ss_ppm += r_ppm * r_ppm;
        ++held_steps;
      }
      sc.e2.push_back(e2);
    }
    if (!ok) break;
    out.rms_ppm.push_back({d, std::sqrt(ss_ppm / static_cast<double>(std::max(1, held_steps)))});
    out.scores.push_back(std::move(sc));
  }
  return out;
}

// The fitted terms of the axis (its degree set) with their sigmas, in deg/h and ppm.
void store_axis_terms(const least_squares::Fit& fit, Axis& ax) {
  const int p = 3 + ax.degree;
  const MatrixXd& cov = fit.covariance;
  ax.bias_dph = fit.x[0] * units::kRadpsToDph;
  ax.bias_sigma_dph = std::sqrt(cov(0, 0)) * units::kRadpsToDph;
  ax.scale_pos_ppm = fit.x[1] * 1e6;
  ax.scale_neg_ppm = fit.x[2] * 1e6;
  ax.scale_pos_sigma_ppm = std::sqrt(cov(1, 1)) * 1e6;
  ax.scale_neg_sigma_ppm = std::sqrt(cov(2, 2)) * 1e6;
  ax.asymmetry_ppm = ax.scale_pos_ppm - ax.scale_neg_ppm;
  ax.asymmetry_sigma_ppm = std::sqrt(std::max(0.0, cov(1, 1) + cov(2, 2) - 2 * cov(1, 2))) * 1e6;
  for (int k = 0; k < ax.degree; ++k) {
    ax.nonlinear_ppm[static_cast<std::size_t>(k)] = fit.x[3 + k] * 1e6;
    ax.nonlinear_sigma_ppm[static_cast<std::size_t>(k)] = std::sqrt(cov(3 + k, 3 + k)) * 1e6;
  }
  ax.covariance_ppm2 = cov.bottomRightCorner(p - 1, p - 1) * 1e12;
}

// Each step's own scale error, with the fitted bias removed, sorted by rate; and the rms of their
// residuals about the fitted model. Needs the axis's terms stored (scale_ppm_at).
void describe_steps(const std::vector<const Segment*>& rows, std::size_t n_statics, const std::vector<double>& y, int j,
                    const least_squares::Fit& fit, Axis& ax) {
  // Residual variance per unit weight: the angle noise density the data show (rad^2/s).
  const double s0sq = fit.s0sq;
  const MatrixXd& cov = fit.covariance;
  double rss_ppm = 0;
  for (std::size_t i = n_statics; i < rows.size(); ++i) {
    const Segment& s = *rows[i];
    const double ref = s.ref_rad()[j];
    Step st;
    st.segment = s.name;
    st.rate_dps = std::copysign(s.peak_table_rate_dps, ref);
    st.angle_deg = ref * kRadToDeg;
    st.duration_s = s.T_s;
    // The rotation's scale error is an average over its ramps and its cruise; the fitted model's
    // own difference between the two moves it to the cruise rate, where IEEE 952 states it.
    const double model_average_ppm = (design_row(s, j, ax.degree).dot(fit.x) - fit.x[0] * s.T_s) / ref * 1e6;
    st.scale_ppm = (y[i] - fit.x[0] * s.T_s) / ref * 1e6 + ax.scale_ppm_at(st.rate_dps) - model_average_ppm;
    st.sigma_ppm = std::sqrt(s0sq * s.T_s + s.T_s * s.T_s * cov(0, 0)) / std::abs(ref) * 1e6;
    st.fit_residual_ppm = (y[i] - design_row(s, j, ax.degree).dot(fit.x)) / ref * 1e6;
    rss_ppm += st.fit_residual_ppm * st.fit_residual_ppm;
    ax.steps.push_back(st);
  }
  std::sort(ax.steps.begin(), ax.steps.end(), [](const Step& a, const Step& b) { return a.rate_dps < b.rate_dps; });
  ax.residual_rms_ppm = std::sqrt(rss_ppm / static_cast<double>(ax.steps.size()));
}

// IEEE 952 nonlinearity: output (1 + s) * input against its least-squares line, over the steps;
// the largest deviation in ppm of the full-scale output, and the rate where it is.
void ieee952_nonlinearity(Axis& ax) {
  MatrixXd A(static_cast<Eigen::Index>(ax.steps.size()), 2);
  VectorXd o(A.rows());
  for (Eigen::Index i = 0; i < A.rows(); ++i) {
    const Step& st = ax.steps[static_cast<std::size_t>(i)];
    A(i, 0) = st.rate_dps;
    A(i, 1) = 1.0;
    o[i] = (1.0 + st.scale_ppm * 1e-6) * st.rate_dps;
    ax.full_scale_dps = std::max(ax.full_scale_dps, std::abs(st.rate_dps));
  }
  const VectorXd line = A.colPivHouseholderQr().solve(o);
  const VectorXd dev = o - A * line;
  Eigen::Index worst = 0;
  dev.cwiseAbs().maxCoeff(&worst);
  const Step& ws = ax.steps[static_cast<std::size_t>(worst)];
  const double fs_out = std::abs(line[0]) * ax.full_scale_dps;
  ax.nonlinearity_ppm_fs = std::abs(dev[worst]) / fs_out * 1e6;
  ax.nonlinearity_sigma_ppm_fs = ws.sigma_ppm * std::abs(ws.rate_dps) / ax.full_scale_dps;
  ax.nonlinearity_at_dps = ws.rate_dps;
}

// The model: gyro j's scale factors and nonlinear terms (zero beyond the degree), with their sigmas.
void store_gyro_scale(int j, const least_squares::Fit& fit, int degree, GyroErrors& gyro, GyroErrors& sigma_gyro) {
  const MatrixXd& cov = fit.covariance;
  gyro.scale_pos[j] = fit.x[1];
  gyro.scale_neg[j] = fit.x[2];
  sigma_gyro.scale_pos[j] = std::sqrt(cov(1, 1));
  sigma_gyro.scale_neg[j] = std::sqrt(cov(2, 2));
  for (int k = 0; k < 3; ++k) {
    gyro.scale_nonlinear(j, k) = k < degree ? fit.x[3 + k] : 0.0;
    sigma_gyro.scale_nonlinear(j, k) = k < degree ? std::sqrt(cov(3 + k, 3 + k)) : 0.0;
  }
}

// Gyro j's test over the ladder into out.axes[j], the model and the notes; false (with a note
// when it had steps) when the ladder does not determine its scale factors.
bool test_gyro(int j, const Ladder& ladder, const Eigen::Matrix3d& D, int max_degree, Result& out,
               GyroErrors& sigma_gyro) {
  char buf[256];
  Axis& ax = out.axes[static_cast<std::size_t>(j)];
  ax.axis = j;
  const auto& steps = ladder.steps_of[static_cast<std::size_t>(j)];
  std::vector<double> cruise_dps;
  for (const Segment* s : steps) cruise_dps.push_back(s->peak_table_rate_dps);
  const std::vector<int> group = group_rates(cruise_dps);
  const int n_rates = group.empty() ? 0 : *std::max_element(group.begin(), group.end()) + 1;
  if (n_rates < 3) {
    if (!steps.empty()) {
      std::snprintf(buf, sizeof buf, "gyro %s: %zu rate(s) turned, the test needs 3 at least", kAxis[j], static_cast<std::size_t>(n_rates));
      out.notes.push_back(buf);
    }
    return false;
  }
  std::vector<const Segment*> rows = statics_in_orientation(ladder.statics, steps);
  if (rows.empty()) {
    out.notes.push_back(std::string("gyro ") + kAxis[j] + ": no static in the orientation of its steps (its bias is unknown)");
    return false;
  }
  const std::size_t n_statics = rows.size();
  rows.insert(rows.end(), steps.begin(), steps.end());
  const std::vector<double> y = beyond_reference_rad(rows, j, D);

  DegreeScores scored = held_back_scores(rows, y, j, n_statics, group, n_rates, max_degree);
  ax.scores = std::move(scored.rms_ppm);
  if (scored.scores.empty()) {
    out.notes.push_back(std::string("gyro ") + kAxis[j] + ": the steps do not determine the scale factors");
    return false;
  }
  // The paired test alone cannot find a cubic on a short ladder, however large (held_back.hpp);
  // a lower degree predicting held-back rates ten times worse in mean square is beaten outright.
  held_back::Rule rule;
  rule.decisive_ratio = 10.0;
  ax.degree = static_cast<int>(held_back::choose(scored.scores, rule));

  const Solved solved = solve(rows, y, j, ax.degree);
  if (!solved.ok) {
    out.notes.push_back(std::string("gyro ") + kAxis[j] + ": the steps do not determine the scale factors");
    return false;
  }
  ax.tested = true;
  store_axis_terms(solved.fit, ax);
  describe_steps(rows, n_statics, y, j, solved.fit, ax);
  ieee952_nonlinearity(ax);
  store_gyro_scale(j, solved.fit, ax.degree, out.model.gyro, sigma_gyro);
  std::snprintf(buf, sizeof buf,
                "gyro %s: %zu steps at %zu rates up to %.0f deg/s, %zu statics; nonlinear degree %d; "
                "IEEE 952 nonlinearity %.2f ppm of full scale (at %+.0f deg/s)",
                kAxis[j], steps.size(), static_cast<std::size_t>(n_rates), ax.full_scale_dps, n_statics, ax.degree,
                ax.nonlinearity_ppm_fs, ax.nonlinearity_at_dps);
  out.notes.push_back(buf);
  return true;
}

}  // namespace

Result RateStepsEstimator::finish(const ImuModel& prior) const {
  Result out;
  out.model = stage_model_from(prior);
  ImuErrorSet& sigma = sigma_to_fill(out.model);
  const Eigen::Matrix3d D = misalignment_matrix(prior.gyro.misalignment_rad);

  Ladder ladder = select_ladder(impl_->segments, impl_->options.min_rotation_deg);
  out.notes = std::move(ladder.notes);
  bool any = false;
  for (int j = 0; j < 3; ++j)
    if (test_gyro(j, ladder, D, impl_->options.max_degree, out, sigma.gyro)) any = true;
  if (!any)
    throw std::runtime_error(
        "rate-steps: no gyro was turned about its own axis at three rates or more with a static in the same "
        "orientation (run the rate-steps or rate-steps-short program)");
  return out;
}

}  // namespace imucal::rate_steps
