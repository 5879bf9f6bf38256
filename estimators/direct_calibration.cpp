#include "estimators/direct_calibration.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <map>
#include <numbers>
#include <sstream>
#include <utility>

#include <Eigen/Geometry>
#include <Eigen/Dense>

#include "core/earth.hpp"
#include "core/table.hpp"
#include "core/units.hpp"
#include "estimators/least_squares.hpp"
#include "estimators/rate_moments.hpp"

namespace imucal::direct {

using Eigen::Matrix3d;
using Eigen::Vector3d;
using units::kDegToRad;

// ---------------------------------------------------------------------------------------------
void SegmentDetector::push(const ImuFrame& f) {
  const double t = static_cast<double>(f.t_ns) * 1e-9;
  if (have_prev_) {
    const bool still = (f.table_deg - prev_deg_).cwiseAbs().maxCoeff() <= still_deg_;
    if (still) {
      if (!in_run_) {
        in_run_ = true;
        run_t0_s_ = prev_t_s_;
      }
      run_t1_s_ = t;
    } else if (in_run_) {
      close_run();
    }
  }
  prev_deg_ = f.table_deg;
  prev_t_s_ = t;
  have_prev_ = true;
}

void SegmentDetector::close_run() {
  in_run_ = false;
  // Leave the settling after a move and the start of the next one out of the static.
  const double t0 = run_t0_s_ + settle_s_, t1 = run_t1_s_ - settle_s_;
  if (t1 - t0 >= min_static_s_) {
    char name[32];
    std::snprintf(name, sizeof name, "static-%02zu", statics_.size() + 1);
    statics_.push_back({name, "static", t0, t1});
  }
}

std::vector<SegmentInfo> SegmentDetector::finish() {
  if (in_run_) close_run();
  return statics_;
}

// ---------------------------------------------------------------------------------------------
std::vector<ReferencePerturbation> reference_perturbations(const RecordingMeta& meta, double gravity_sigma_mps2) {
  std::vector<ReferencePerturbation> out;
  if (gravity_sigma_mps2 > 0) {
    RecordingMeta m = meta;
    m.site.gravity_mps2 = earth::site_gravity_mps2(meta.site) + gravity_sigma_mps2;
    out.push_back({"site.gravity_mps2", std::move(m), gravity_sigma_mps2});
  }
  if (!meta.table || !meta.table->sigma) return out;
  const table::TableGeometry& sigma = *meta.table->sigma;
  // Moved about the values the certificate gives: the reference applies them, the budget covers
  // what is left, their uncertainty.
  const table::TableGeometry base = meta.table->geometry.value_or(table::TableGeometry{});
  auto moved = [&](const std::string& source, double sigma_rad, const auto& move) {
    RecordingMeta m = meta;
    table::TableGeometry g = base;
    move(g);
    m.table->geometry = g;
    out.push_back({source, std::move(m), sigma_rad * units::kRadToArcsec});
  };
  using Pair = std::array<double, 2> table::TableGeometry::*;
  const std::pair<const char*, Pair> pairs[] = {{"table.outer_tilt_arcsec", &table::TableGeometry::outer_tilt_rad},
                                                {"table.middle_axis_arcsec", &table::TableGeometry::middle_axis_rad},
                                                {"table.inner_axis_arcsec", &table::TableGeometry::inner_axis_rad}};
  for (const auto& [source, member] : pairs)
    for (std::size_t i = 0; i < 2; ++i)
      if ((sigma.*member)[i] > 0)
        moved(source, (sigma.*member)[i], [&](table::TableGeometry& g) { (g.*member)[i] += (sigma.*member)[i]; });
  const char* kEncoder[3] = {"table.encoder_error_arcsec.outer", "table.encoder_error_arcsec.middle",
                             "table.encoder_error_arcsec.inner"};
  for (std::size_t axis = 0; axis < 3; ++axis) {
    for (const table::EncoderHarmonic& s : sigma.encoder_error[axis]) {
      // The certified harmonic of this order, if the geometry gives it: its phase is then known.
      const table::EncoderHarmonic* known = nullptr;
      for (const table::EncoderHarmonic& h : base.encoder_error[axis])
        if (h.k == s.k) known = &h;
      const double phase_rad = known ? known->phase_rad : 0.0;
      const double quadrature_sigma_rad = known ? known->amplitude_rad * s.phase_rad : s.amplitude_rad;
      // An added term of the same order: a sin(k th + phi) + d sin(k th + psi) is the sum, so the
      // reference moves exactly as the harmonic does in that quadrature.
      const std::pair<double, double> quadratures[2] = {{s.amplitude_rad, phase_rad},
                                                        {quadrature_sigma_rad, phase_rad + 0.5 * std::numbers::pi}};
      for (const auto& [amplitude_rad, phase] : quadratures)
        if (amplitude_rad > 0)
          moved(kEncoder[axis], amplitude_rad, [&](table::TableGeometry& g) {
            g.encoder_error[axis].push_back({s.k, amplitude_rad, phase});
          });
    }
  }
  return out;
}

double gravity_sigma_mps2(const RecordingMeta& meta, const Options& options) {
  return options.gravity_sigma_mps2.value_or(earth::site_gravity_sigma_mps2(meta.site));
}

std::map<std::string, double> bench_source_sigmas(const RecordingMeta& meta, const Options& options) {
  std::map<std::string, double> out;
  if (options.type_b)
    for (const ReferencePerturbation& p : reference_perturbations(meta, gravity_sigma_mps2(meta, options)))
      out[p.source] = std::max(out[p.source], p.sigma);
  return out;
}

DirectCalibrator::DirectCalibrator(const RecordingMeta& meta, const Options& options)
    : meta_(meta), options_(options), reference_(meta) {
  if (options.type_b)
    for (const ReferencePerturbation& p : reference_perturbations(meta, gravity_sigma_mps2(meta, options))) {
      perturbation_sources_.push_back(p.source);
      perturbed_references_.emplace_back(p.meta);
    }
  for (const SegmentInfo& s : meta.segments)
    if (s.kind == "static" || s.kind == "tilt") statics_.push_back(s);
  std::sort(statics_.begin(), statics_.end(), [](const SegmentInfo& a, const SegmentInfo& b) { return a.t0_s < b.t0_s; });
  g_mps2_ = earth::site_gravity_mps2(meta.site);
  dt_nominal_s_ = 1.0 / meta.rate_hz;
  intervals_.reserve(statics_.size() * 2 + 1);
}

void DirectCalibrator::open_interval(const std::string& name, bool is_static, double t0_s) {
  Interval iv;
  iv.name = name;
  iv.is_static = is_static;
  iv.t0_s = t0_s;
  iv.t1_s = t0_s;
  iv.perturbed.resize(perturbed_references_.size());
  intervals_.push_back(iv);
  current_ = &intervals_.back();
}

namespace {

// One frame's reference into an interval's sums: the one rule for the recording's reference and
// for each perturbed one.
void add_frame(ReferenceSums& r, const Vector3d& wdt_o, const Vector3d& f_rest_o, double dt_s, bool first_of_static) {
  for (int k = 0; k < 3; ++k) (wdt_o[k] >= 0 ? r.ref_pos_rad[k] : r.ref_neg_rad[k]) += wdt_o[k];
  if (first_of_static) r.f_o_mps2 = f_rest_o;
  r.f_dt_o += f_rest_o * dt_s;
  r.nonlinear_moments_rad += rate_moments::of(wdt_o, dt_s);
}

}  // namespace

void DirectCalibrator::push(const ImuFrame& f) {
  if (!have_prev_) {
    prev_ = f;
    have_prev_ = true;
    return;
  }
  const double t = static_cast<double>(f.t_ns) * 1e-9, t_prev = static_cast<double>(prev_.t_ns) * 1e-9;
  const double dt = t - t_prev;
  // Every frame, so that each knows the table's acceleration from the one before.
  const Vector3d wdt_o = reference_.next_increment_o_rad(prev_.table_deg, f.table_deg, dt);
  constexpr double eps = 1e-7;
  while (next_static_ < statics_.size() && t > statics_[next_static_].t1_s + eps) ++next_static_;
  const bool in_static = next_static_ < statics_.size() && t > statics_[next_static_].t0_s + eps;
  std::string name;
  if (in_static) {
    name = statics_[next_static_].name;
  } else if (next_static_ > 0 && next_static_ < statics_.size()) {
    name = statics_[next_static_ - 1].name + " -> " + statics_[next_static_].name;
  }
  if (name.empty()) {  // before the first static or after the last: no rest-to-rest reference
    prev_ = f;
    current_ = nullptr;
    return;
  }
  if (!current_ || current_->name != name) open_interval(name, in_static, t_prev);
  Interval& iv = *current_;
  if (dt > options_.gap_factor * dt_nominal_s_ || dt <= 0) iv.gap = true;

  iv.moved_axes_rad += (f.table_deg - prev_.table_deg).cwiseAbs() * kDegToRad;
  const bool first_of_static = iv.frames == 0 && iv.is_static;
  // Specific force at rest: gravity reaction resolved in o.
  add_frame(iv, wdt_o, reference_.specific_force_at_rest_o_mps2(f.table_deg), dt, first_of_static);
  // The perturbed references only inside intervals: the statics and the moves between them are
  // one unbroken run of frames, so each one's acceleration from the frame before holds there.
  for (std::size_t p = 0; p < perturbed_references_.size(); ++p) {
    table_reference::FrameReference& ref = perturbed_references_[p];
    add_frame(iv.perturbed[p], ref.next_increment_o_rad(prev_.table_deg, f.table_deg, dt),
              ref.specific_force_at_rest_o_mps2(f.table_deg), dt, first_of_static);
  }
  iv.sum_dtheta += f.dtheta_rad;
  iv.sum_dv += f.dv_mps;
  iv.sumsq_dtheta += f.dtheta_rad.cwiseAbs2();
  iv.sumsq_dv += f.dv_mps.cwiseAbs2();
  iv.T_s += dt;
  iv.t1_s = t;
  ++iv.frames;
  prev_ = f;
}

namespace {

const char* kAxis[3] = {"x", "y", "z"};

// Off-diagonal misalignment entries of row j of D: (column k, sign, key) for the two k != j.
struct OffDiag {
  int k;
  double sign;
  double Misalignment::*member;
};
const OffDiag kOffDiag[3][2] = {
    {{1, +1.0, &Misalignment::xz}, {2, -1.0, &Misalignment::xy}},
    {{0, -1.0, &Misalignment::yz}, {2, +1.0, &Misalignment::yx}},
    {{0, +1.0, &Misalignment::zy}, {1, -1.0, &Misalignment::zx}},
};

}  // namespace

Selection select_intervals(const std::vector<Interval>& intervals, const Options& options) {
  Selection sel;
  for (const Interval& iv : intervals) {
    if (iv.frames < 2) continue;
    if (iv.is_static) {
      sel.statics.push_back(&iv);
      continue;
    }
    int moving = 0;
    for (int k = 0; k < 3; ++k) moving += iv.moved_axes_rad[k] > 1e-8;
    const double turned = iv.moved_axes_rad.maxCoeff();
    if (iv.gap) {
      sel.notes.push_back("rotation '" + iv.name + "' left out: a gap in the frames (never integrated across)");
    } else if (moving > 1) {
      sel.notes.push_back("rotation '" + iv.name + "' left out: several table axes moved together");
    } else if (turned >= options.min_rotation_rad) {
      sel.rotations.push_back(&iv);
    }
  }
  return sel;
}

std::string SensorDesign::key(std::size_t c) const {
  const Column& col = columns.at(c);
  const std::string triad = gyro ? "gyro." : "accel.";
  switch (col.kind) {
    case Column::Kind::Bias: return triad + (gyro ? "bias_dph." : "bias_mps2.") + kAxis[axis];
    case Column::Kind::ScalePos: return triad + "scale_pos_ppm." + kAxis[axis];
    case Column::Kind::ScaleNeg: return triad + "scale_neg_ppm." + kAxis[axis];
    case Column::Kind::Scale: return triad + "scale_ppm." + kAxis[axis];
    case Column::Kind::Angle: return triad + "misalignment_arcsec." + col.angle_name;
  }
  return {};
}

namespace {

// The two angles of row j of D, as columns (in kOffDiag's order).
Column angle_column(int j, int c) {
  const OffDiag& od = kOffDiag[j][c];
  for (const MisalignmentKey& k : kMisalignmentKeys)
    if (k.member == od.member) return {Column::Kind::Angle, k.member, k.name};
  return {};
}

}  // namespace

SensorDesign accel_design(int j, const Selection& sel, const AccelErrors& at) {
  SensorDesign d;
  d.gyro = false;
  d.axis = j;
  d.columns = {{Column::Kind::Bias}, {Column::Kind::Scale}, angle_column(j, 0), angle_column(j, 1)};
  d.rows = sel.statics;
  const auto n = static_cast<Eigen::Index>(d.rows.size());
  d.A.resize(n, 4);
  d.b.resize(n);
  d.w.resize(n);
  for (Eigen::Index i = 0; i < n; ++i) {
    const Interval& s = *d.rows[static_cast<std::size_t>(i)];
    const Vector3d& f = s.f_o_mps2;
    d.A(i, 0) = 1.0;
    d.A(i, 1) = f[j];
    for (int c = 0; c < 2; ++c) {
      const OffDiag& od = kOffDiag[j][c];
      d.A(i, 2 + c) = od.sign * (1.0 + at.scale[od.k]) * f[od.k];
    }
    // Mean specific-force residual of the static, less what K2 and K3 (known) add at f_j.
    const double a_g = f[j] / units::kStandardGravity_mps2;
    const double nonlinear = (at.k2_per_g[j] + at.k3_per_g2[j] * a_g) * a_g * f[j];
    d.b(i) = s.sum_dv[j] / s.T_s - f[j] - nonlinear;
    d.w(i) = s.T_s;                       // white noise: variance of the mean falls as 1/T
  }
  return d;
}

SensorDesign gyro_design(int j, const Selection& sel, const GyroErrors& at) {
  SensorDesign d;
  d.gyro = true;
  d.axis = j;
  d.columns = {{Column::Kind::Bias}, {Column::Kind::ScalePos}, {Column::Kind::ScaleNeg}, angle_column(j, 0),
               angle_column(j, 1)};
  d.rows = sel.statics;
  d.rows.insert(d.rows.end(), sel.rotations.begin(), sel.rotations.end());
  const auto n = static_cast<Eigen::Index>(d.rows.size());
  d.A.resize(n, 5);
  d.b.resize(n);
  d.w.resize(n);
  for (Eigen::Index i = 0; i < n; ++i) {
    const Interval& e = *d.rows[static_cast<std::size_t>(i)];
    // Input through the current scale factors of axis k, split by sign as the FOG sees it.
    auto scaled = [&](int k) {
      return (1.0 + at.scale_pos[k]) * e.ref_pos_rad[k] + (1.0 + at.scale_neg[k]) * e.ref_neg_rad[k];
    };
    d.A(i, 0) = e.T_s;
    d.A(i, 1) = e.ref_pos_rad[j];
    d.A(i, 2) = e.ref_neg_rad[j];
    for (int c = 0; c < 2; ++c) d.A(i, 3 + c) = kOffDiag[j][c].sign * scaled(kOffDiag[j][c].k);
    // Summed-angle residual, less what the known g-sensitivity and scale nonlinearity add.
    const double g_sensitivity = at.g_sensitivity_radps_per_g.row(j).dot(e.f_dt_o) / units::kStandardGravity_mps2;
    const double nonlinear = at.scale_nonlinear.row(j).dot(e.nonlinear_moments_rad.row(j));
    d.b(i) = e.sum_dtheta[j] - (e.ref_pos_rad[j] + e.ref_neg_rad[j]) - g_sensitivity - nonlinear;
    d.w(i) = 1.0 / e.T_s;  // angle random walk: variance of the summed angle grows as T
  }
  return d;
}

double& coefficient(GyroErrors& g, const Column& c, int axis) {
  switch (c.kind) {
    case Column::Kind::Bias: return g.bias_radps[axis];
    case Column::Kind::ScalePos: return g.scale_pos[axis];
    case Column::Kind::ScaleNeg: return g.scale_neg[axis];
    case Column::Kind::Angle: return g.misalignment_rad.*(c.angle);
    case Column::Kind::Scale: break;
  }
  throw std::logic_error("stage direct: a gyro has no single scale factor column");
}

double& coefficient(AccelErrors& a, const Column& c, int axis) {
  switch (c.kind) {
    case Column::Kind::Bias: return a.bias_mps2[axis];
    case Column::Kind::Scale: return a.scale[axis];
    case Column::Kind::Angle: return a.misalignment_rad.*(c.angle);
    case Column::Kind::ScalePos:
    case Column::Kind::ScaleNeg: break;
  }
  throw std::logic_error("stage direct: an accelerometer has one scale factor, not one per sign");
}

namespace {

// The entry of column c of a sensor's design in a set of errors (a sigma or a budget source).
double& entry(ImuErrorSet& set, const SensorDesign& d, std::size_t c) {
  return d.gyro ? coefficient(set.gyro, d.columns[c], d.axis) : coefficient(set.accel, d.columns[c], d.axis);
}

// The six designs of stage 1 (accelerometers x y z, gyros x y z) over `intervals` at the errors
// the fit converged to, each with its solution.
struct SensorFit {
  SensorDesign design;
  Eigen::VectorXd x;
};
std::vector<SensorFit> sensor_fits(const std::vector<Interval>& intervals, const Options& options,
                                   const GyroErrors& gyro_at, const AccelErrors& accel_at) {
  const Selection sel = select_intervals(intervals, options);
  std::vector<SensorFit> fits;
  for (int j = 0; j < 3; ++j) fits.push_back({accel_design(j, sel, accel_at), {}});
  for (int j = 0; j < 3; ++j) fits.push_back({gyro_design(j, sel, gyro_at), {}});
  for (SensorFit& f : fits) f.x = least_squares::solve(f.design.A, f.design.b, f.design.w).x;
  return fits;
}

}  // namespace

std::map<std::string, ImuErrorSet> uncertainty_budget(const std::vector<Interval>& intervals, const Options& options,
                                                      const std::vector<std::string>& perturbation_sources,
                                                      const GyroErrors& gyro, const AccelErrors& accel,
                                                      const ImuErrorSet& start_sigma, ImuErrorSet& sigma,
                                                      const std::map<std::string, ImuErrorSet>& carried) {
  // Every shift is measured from the solution at the converged errors with the recording's own
  // reference, so that it is the source's effect alone (the fit's iteration is not in it).
  const std::vector<SensorFit> nominal = sensor_fits(intervals, options, gyro, accel);
  // Variances per source; several parameters of one source (a tilt's two components, a harmonic's
  // two quadratures, the three K2) are independent and add as variances.
  std::map<std::string, ImuErrorSet> variance;
  auto add_shifts = [&](const std::string& source, const std::vector<SensorFit>& moved) {
    ImuErrorSet& v = variance[source];
    for (std::size_t s = 0; s < nominal.size(); ++s)
      for (std::size_t c = 0; c < nominal[s].design.columns.size(); ++c) {
        const double shift = moved[s].x[static_cast<Eigen::Index>(c)] - nominal[s].x[static_cast<Eigen::Index>(c)];
        entry(v, nominal[s].design, c) += shift * shift;
      }
  };

  // The table's geometry and the site's g: the intervals with their perturbed reference sums.
  for (std::size_t p = 0; p < perturbation_sources.size(); ++p) {
    std::vector<Interval> moved = intervals;
    for (Interval& iv : moved) static_cast<ReferenceSums&>(iv) = iv.perturbed.at(p);
    add_shifts(perturbation_sources[p], sensor_fits(moved, options, gyro, accel));
  }

  // The start model's terms stage 1 removes without estimating them (CONVENTIONS.md, "Nonlinear
  // terms"), each moved by the start model's sigma of it: the designs take them as known.
  auto start_term = [&](const std::string& source, double sigma_of_term, const auto& move) {
    if (!(sigma_of_term > 0)) return;
    GyroErrors g = gyro;
    AccelErrors a = accel;
    move(g, a, sigma_of_term);
    add_shifts(source, sensor_fits(intervals, options, g, a));
  };
  for (int j = 0; j < 3; ++j)
    for (int k = 0; k < 3; ++k) {
      start_term(start_model_source::kGyroScaleNonlinear, start_sigma.gyro.scale_nonlinear(j, k),
                 [&](GyroErrors& g, AccelErrors&, double d) { g.scale_nonlinear(j, k) += d; });
      start_term(start_model_source::kGyroGSensitivity, start_sigma.gyro.g_sensitivity_radps_per_g(j, k),
                 [&](GyroErrors& g, AccelErrors&, double d) { g.g_sensitivity_radps_per_g(j, k) += d; });
    }
  for (int j = 0; j < 3; ++j) {
    start_term(start_model_source::kAccelK2, start_sigma.accel.k2_per_g[j],
               [&](GyroErrors&, AccelErrors& a, double d) { a.k2_per_g[j] += d; });
    start_term(start_model_source::kAccelK3, start_sigma.accel.k3_per_g2[j],
               [&](GyroErrors&, AccelErrors& a, double d) { a.k3_per_g2[j] += d; });
  }

  // This stage's coefficients leave the budget it was given (their sources are this run's now);
  // the rest of it (another stage's coefficients) is carried over.
  std::map<std::string, ImuErrorSet> budget = carried;
  for (auto& [source, set] : budget)
    for (const SensorFit& f : nominal)
      for (std::size_t c = 0; c < f.design.columns.size(); ++c) entry(set, f.design, c) = 0.0;
  // Type A, each type B, and their root-sum-square as the coefficient's sigma (the sources are
  // independent of each other and of the noise).
  for (const SensorFit& f : nominal)
    for (std::size_t c = 0; c < f.design.columns.size(); ++c) {
      double& s = entry(sigma, f.design, c);
      entry(budget["type_a"], f.design, c) = s;
      double combined_sq = s * s;
      for (auto& [source, v] : variance) {
        const double contribution = std::sqrt(entry(v, f.design, c));
        entry(budget[source], f.design, c) = contribution;
        combined_sq += contribution * contribution;
      }
      s = std::sqrt(combined_sq);
    }
  return budget;
}

namespace {

// What the selected intervals cannot determine, each said with the motion that would: the
// accelerometers need statics with each axis up and down, the gyros rotations of both signs about
// each axis and statics for their biases. Empty when the recording determines every coefficient.
std::vector<std::string> undetermined_by_motion(const Selection& sel, double g_mps2) {
  const std::vector<const Interval*>& statics = sel.statics;
  const std::vector<const Interval*>& rotations = sel.rotations;
  std::vector<std::string> missing;
  // ---------------- accelerometers: multi-position in the gravity field
  const auto ns = static_cast<Eigen::Index>(statics.size());
  if (ns < 4) missing.push_back("accelerometer biases, scale factors and angles: " + std::to_string(ns) +
                                " static positions (need each axis up and down and the others horizontal, 6 at least)");
  for (int j = 0; j < 3 && ns >= 4; ++j) {
    double fmax = -1e9, fmin = 1e9;
    for (const Interval* s : statics) {
      fmax = std::max(fmax, s->f_o_mps2[j]);
      fmin = std::min(fmin, s->f_o_mps2[j]);
    }
    if (fmax < 0.5 * g_mps2 || fmin > -0.5 * g_mps2)
      missing.push_back(std::string("accelerometer ") + kAxis[j] + " bias_mps2 and scale_ppm: the " + kAxis[j] +
                        " axis was never pointed both up and down (add static positions with it vertical, both ways)");
  }
  // ---------------- gyros: rotations of both signs about each axis
  for (int j = 0; j < 3; ++j) {
    double pos = 0, neg = 0;
    for (const Interval* r : rotations) {
      pos += r->ref_pos_rad[j];
      neg += r->ref_neg_rad[j];
    }
    if (pos < 1.0)
      missing.push_back(std::string("gyro ") + kAxis[j] + " scale_pos_ppm (and the angles of the other gyros about " +
                        kAxis[j] + "): no positive rotation about the " + kAxis[j] +
                        " axis (add a single-axis rate run with positive rate about it)");
    if (neg > -1.0)
      missing.push_back(std::string("gyro ") + kAxis[j] + " scale_neg_ppm: no negative rotation about the " + kAxis[j] +
                        " axis (add a single-axis rate run with negative rate about it)");
  }
  if (statics.empty()) missing.push_back("gyro biases: no static interval");
  return missing;
}

// The white noise of the statics: per-sample variance about each static's mean, as a density.
// It gives the ARW and VRW, and the variance per unit weight the fits' sigmas are scaled with
// while their residuals agree with it (least_squares::variance_factor): a static's mean specific
// force has variance VRW^2 / T (weight T), an interval's summed angle ARW^2 T (weight 1/T).
struct WhiteNoise {
  Vector3d arw_sq_rad2_per_s;  // per gyro, (rad/sqrt(s))^2
  Vector3d vrw_sq_m2_per_s3;  // per accelerometer, (m/s/sqrt(s))^2
};
WhiteNoise white_noise_of_statics(const std::vector<const Interval*>& statics) {
  Vector3d var_g = Vector3d::Zero(), var_a = Vector3d::Zero();
  double n_used = 0, T_used = 0;
  for (const Interval* s : statics) {
    const auto n = static_cast<double>(s->frames);
    const Vector3d mg = s->sum_dtheta / n, ma = s->sum_dv / n;
    var_g += (s->sumsq_dtheta / n - mg.cwiseAbs2()) * n;
    var_a += (s->sumsq_dv / n - ma.cwiseAbs2()) * n;
    n_used += n;
    T_used += s->T_s;
  }
  const double dt = n_used > 0 ? T_used / n_used : 0.0;
  const Vector3d arw_sq = dt > 0 ? Vector3d((var_g / n_used / dt).cwiseMax(0)) : Vector3d::Zero();
  const Vector3d vrw_sq = dt > 0 ? Vector3d((var_a / n_used / dt).cwiseMax(0)) : Vector3d::Zero();
  return {arw_sq, vrw_sq};
}

// The accelerometers' bias, scale and angles from the statics, from zero: four passes, each
// design linearised about the previous pass's errors (the angles' columns carry the scale). Their
// type A sigma into `sigma_accel`; returns the residual variance per unit weight, the mean of the
// three accelerometers' ((m/s^2)^2 s).
double fit_accelerometers(const Selection& sel, const Vector3d& vrw_sq_m2_per_s3, AccelErrors& acc,
                          AccelErrors& sigma_accel) {
  acc.bias_mps2.setZero();
  acc.scale.setZero();
  acc.misalignment_rad = {};
  double acc_rms_sq = 0;
  for (int iter = 0; iter < 4; ++iter) {
    AccelErrors next = acc;
    acc_rms_sq = 0;
    for (int j = 0; j < 3; ++j) {
      const SensorDesign d = accel_design(j, sel, acc);
      if (least_squares::min_scaled_eigenvalue(d.A, d.w) < 1e-10)
        throw UndeterminedError(std::string("stage direct: accelerometer ") + kAxis[j] +
                                ": bias, scale and angles are not separable with these positions (add positions with "
                                "each of the other axes vertical)");
      const least_squares::Fit fit = least_squares::solve(d.A, d.b, d.w);
      const double s0sq = least_squares::variance_factor(fit, vrw_sq_m2_per_s3[j]);
      for (std::size_t c = 0; c < d.columns.size(); ++c) {
        const auto i = static_cast<Eigen::Index>(c);
        coefficient(next, d.columns[c], j) = fit.x[i];
        coefficient(sigma_accel, d.columns[c], j) = std::sqrt(fit.normal_inverse(i, i) * s0sq);
      }
      acc_rms_sq += fit.s0sq / 3.0;
    }
    acc.bias_mps2 = next.bias_mps2;
    acc.scale = next.scale;
    acc.misalignment_rad = next.misalignment_rad;
  }
  return acc_rms_sq;
}

// The gyros' bias, scale factor per sign and angles: statics against the Earth rate, rotations
// against the table; four passes from zero as for the accelerometers. Their type A sigma into
// `sigma_gyro`; returns the residual variance per unit weight, the mean of the three gyros'
// (rad^2 / s).
double fit_gyros(const Selection& sel, const Vector3d& arw_sq_rad2_per_s, GyroErrors& gy, GyroErrors& sigma_gyro) {
  gy.bias_radps.setZero();
  gy.scale_pos.setZero();
  gy.scale_neg.setZero();
  gy.misalignment_rad = {};
  double gyro_rms_sq = 0;
  for (int iter = 0; iter < 4; ++iter) {
    GyroErrors next = gy;
    gyro_rms_sq = 0;
    for (int j = 0; j < 3; ++j) {
      const SensorDesign d = gyro_design(j, sel, gy);
      if (least_squares::min_scaled_eigenvalue(d.A, d.w) < 1e-12)
        throw UndeterminedError(std::string("stage direct: gyro ") + kAxis[j] +
                                ": bias, scale factors and angles are not separable (add statics and single-axis "
                                "rotations of both signs about every axis)");
      const least_squares::Fit fit = least_squares::solve(d.A, d.b, d.w);
      const double s0sq = least_squares::variance_factor(fit, arw_sq_rad2_per_s[j]);
      for (std::size_t c = 0; c < d.columns.size(); ++c) {
        const auto i = static_cast<Eigen::Index>(c);
        coefficient(next, d.columns[c], j) = fit.x[i];
        coefficient(sigma_gyro, d.columns[c], j) = std::sqrt(fit.normal_inverse(i, i) * s0sq);
      }
      gyro_rms_sq += fit.s0sq / 3.0;
    }
    gy.bias_radps = next.bias_radps;
    gy.scale_pos = next.scale_pos;
    gy.scale_neg = next.scale_neg;
    gy.misalignment_rad = next.misalignment_rad;
  }
  return gyro_rms_sq;
}

// The terms stage 1 takes from the start model (a rate-steps or tumble model), not estimating
// them: said, so that nobody reads their sigma as this run's. Empty when there are none.
std::string start_model_terms_note(const GyroErrors& gy, const AccelErrors& acc) {
  std::vector<std::string> fixed;
  if (!gy.scale_nonlinear.isZero(0.0)) fixed.emplace_back("gyro scale_nonlinear_ppm");
  if (!gy.g_sensitivity_radps_per_g.isZero(0.0)) fixed.emplace_back("gyro g_sensitivity_dph_per_g");
  if (!acc.k2_per_g.isZero(0.0)) fixed.emplace_back("accel k2_ug_per_g2");
  if (!acc.k3_per_g2.isZero(0.0)) fixed.emplace_back("accel k3_ug_per_g3");
  if (fixed.empty()) return {};
  std::string text = "stage direct: taken from the start model and removed from the measurements (not estimated here): ";
  for (std::size_t i = 0; i < fixed.size(); ++i) text += (i ? ", " : "") + fixed[i];
  return text;
}

}  // namespace

Result DirectCalibrator::finish(const ImuModel& seed) const {
  if (seed.frame != "instrument")
    throw std::invalid_argument("stage direct: give the seed model in the instrument frame");
  Result res;
  res.model = seed;
  ImuErrorSet sigma = seed.sigma.value_or(ImuErrorSet{});

  Selection sel = select_intervals(intervals_, options_);
  res.notes = std::move(sel.notes);
  res.statics = static_cast<int>(sel.statics.size());
  res.rotations = static_cast<int>(sel.rotations.size());
  for (const Interval* s : sel.statics) res.static_time_s += s->T_s;

  if (const std::vector<std::string> missing = undetermined_by_motion(sel, g_mps2_); !missing.empty()) {
    std::string msg = "stage direct: the recording cannot determine:";
    for (const auto& m : missing) msg += "\n  - " + m;
    throw UndeterminedError(msg);
  }

  const WhiteNoise noise = white_noise_of_statics(sel.statics);
  AccelErrors& acc = res.model.accel;
  // rms per unit weight is in (m/s^2) sqrt(s): report it for a 1 s average
  res.accel_residual_rms_mps2 = std::sqrt(fit_accelerometers(sel, noise.vrw_sq_m2_per_s3, acc, sigma.accel));
  GyroErrors& gy = res.model.gyro;
  res.gyro_residual_rms_rad = std::sqrt(fit_gyros(sel, noise.arw_sq_rad2_per_s, gy, sigma.gyro));

  gy.noise.arw_rad_rts = noise.arw_sq_rad2_per_s.cwiseSqrt().mean();
  acc.noise.vrw_mps_rts = noise.vrw_sq_m2_per_s3.cwiseSqrt().mean();

  // ---------------- the uncertainty budget: sigma so far is the fit's own (type A)
  const ImuErrorSet start_sigma = options_.type_b ? seed.sigma.value_or(ImuErrorSet{}) : ImuErrorSet{};
  res.model.budget = uncertainty_budget(intervals_, options_, perturbation_sources_, gy, acc, start_sigma, sigma,
                                        seed.budget);
  res.model.sigma = sigma;
  res.model.frame = "instrument";
  if (std::string note = start_model_terms_note(gy, acc); !note.empty()) res.notes.push_back(std::move(note));
  char buf[200];
  std::snprintf(buf, sizeof buf, "stage direct: %d statics (%.0f s), %d rotations used", res.statics, res.static_time_s,
                res.rotations);
  res.notes.insert(res.notes.begin(), buf);
  return res;
}

ImuModel to_body_frame(const ImuModel& m) {
  if (m.frame == "body") return m;
  ImuModel b = m;
  b.frame = "body";
  // Exactly, not to first order: at 60" angles and 300 ppm scale errors the second-order terms
  // (angle x angle, angle x scale) reach 0.02-0.05", the size of stage 3's sigmas. Channel j
  // senses row j of D S (CONVENTIONS.md), so the accelerometers' sensitive axes are those rows:
  // X along the x row, Y in the plane of the x and y rows, Z = X x Y.
  const AccelErrors& a = m.accel;
  const Matrix3d M_a = misalignment_matrix(a.misalignment_rad) * (Vector3d::Ones() + a.scale).asDiagonal();
  const Vector3d X = M_a.row(0).transpose().normalized();
  const Vector3d Z = X.cross(M_a.row(1).transpose()).normalized();
  Matrix3d C_b_o;  // v_o = C_b_o v_b: the body axes are its columns
  C_b_o << X, Z.cross(X), Z;
  const Eigen::AngleAxisd aa(C_b_o);
  b.body_to_instrument_rad = Vector3d(aa.angle() * aa.axis());
  // In b the accelerometers' D S is lower triangular: D with unit diagonal times the scale.
  const Matrix3d L_a = M_a * C_b_o;
  b.accel.scale = L_a.diagonal() - Vector3d::Ones();
  const Matrix3d D_a = L_a * L_a.diagonal().cwiseInverse().asDiagonal();
  Misalignment am;
  am.yz = -D_a(1, 0);
  am.zy = D_a(2, 0);
  am.zx = -D_a(2, 1);
  b.accel.misalignment_rad = am;  // xy, xz, yx exactly zero
  // The gyros the same way for each sign; D from the + scale (the - one differs by the scale
  // asymmetry times an angle, 1e-9 rad).
  const Matrix3d D_g = misalignment_matrix(m.gyro.misalignment_rad);
  const Matrix3d L_pos = D_g * (Vector3d::Ones() + m.gyro.scale_pos).asDiagonal() * C_b_o;
  const Matrix3d L_neg = D_g * (Vector3d::Ones() + m.gyro.scale_neg).asDiagonal() * C_b_o;
  b.gyro.scale_pos = L_pos.diagonal() - Vector3d::Ones();
  b.gyro.scale_neg = L_neg.diagonal() - Vector3d::Ones();
  const Matrix3d D_gb = L_pos * L_pos.diagonal().cwiseInverse().asDiagonal();
  Misalignment gm;
  gm.xz = D_gb(0, 1);
  gm.xy = -D_gb(0, 2);
  gm.yz = -D_gb(1, 0);
  gm.yx = D_gb(1, 2);
  gm.zy = D_gb(2, 0);
  gm.zx = -D_gb(2, 1);
  b.gyro.misalignment_rad = gm;
  // The nonlinear terms stay with their channels (an arcsecond-size rotation moves the input they
  // see by 1e-5 of itself). g-sensitivity acts on the specific force along o, f_o = C_b_o f_b: its
  // columns turn into b.
  b.gyro.g_sensitivity_radps_per_g = m.gyro.g_sensitivity_radps_per_g * C_b_o;
  if (m.sigma) {
    // The body axes are themselves estimated: add their variance to the shifted angles.
    const Misalignment& sa = m.sigma->accel.misalignment_rad;
    const Vector3d sr(sa.yx, sa.xy, sa.xz);
    auto widen = [&](Misalignment s) {
      s.xz = std::hypot(s.xz, sr.z());
      s.yz = std::hypot(s.yz, sr.z());
      s.xy = std::hypot(s.xy, sr.y());
      s.zy = std::hypot(s.zy, sr.y());
      s.yx = std::hypot(s.yx, sr.x());
      s.zx = std::hypot(s.zx, sr.x());
      return s;
    };
    b.sigma->gyro.misalignment_rad = widen(m.sigma->gyro.misalignment_rad);
    Misalignment acc_sigma = widen(m.sigma->accel.misalignment_rad);
    acc_sigma.xy = acc_sigma.xz = acc_sigma.yx = 0.0;
    b.sigma->accel.misalignment_rad = acc_sigma;
  }
  return b;
}

}  // namespace imucal::direct
