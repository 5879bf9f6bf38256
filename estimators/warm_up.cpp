#include "estimators/warm_up.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <stdexcept>

#include <Eigen/Dense>

#include "core/turn_on.hpp"
#include "core/units.hpp"
#include "estimators/table_reference.hpp"

namespace imucal::warm_up {

namespace {

constexpr double kUgToMps2 = 1e-6 * units::kStandardGravity_mps2;

struct Bin {
  Eigen::Vector3d sum_dtheta_rad = Eigen::Vector3d::Zero(), sum_dv_mps = Eigen::Vector3d::Zero();
  double T_s = 0;
  double sum_t_dt = 0;  // for the bin's mean time since power-on
  Eigen::Vector3d first_deg = Eigen::Vector3d::Zero();
  bool used = false;
};

// The two linear terms at one time constant: y = c + a exp(-t / tau), least squares.
struct LinearFit {
  double c = 0, a = 0, rss = std::numeric_limits<double>::infinity();
};
LinearFit fit_at(const std::vector<double>& t, const std::vector<double>& y, double tau) {
  double n = 0, sx = 0, sxx = 0, sy = 0, sxy = 0;
  for (std::size_t k = 0; k < t.size(); ++k) {
    const double x = std::exp(-t[k] / tau);
    n += 1;
    sx += x;
    sxx += x * x;
    sy += y[k];
    sxy += x * y[k];
  }
  LinearFit f;
  const double det = n * sxx - sx * sx;
  if (!(det > 1e-12 * n * sxx)) return f;  // exp(-t/tau) constant over the bins: no shape to fit
  f.a = (n * sxy - sx * sy) / det;
  f.c = (sy - f.a * sx) / n;
  f.rss = 0;
  for (std::size_t k = 0; k < t.size(); ++k) {
    const double r = y[k] - f.c - f.a * std::exp(-t[k] / tau);
    f.rss += r * r;
  }
  return f;
}

// One channel: the time constant by a log grid and a golden-section search, then the sigmas of
// (settled, amplitude, time constant) from the Gauss-Newton normal matrix at the optimum.
Channel fit_channel(const std::vector<double>& t, const std::vector<double>& y, double band, double chi2_threshold,
                    std::vector<double>& deviation) {
  Channel ch;
  ch.band = band;
  const std::size_t n = t.size();
  const double T = t.back();
  double mean = 0;
  for (double v : y) mean += v;
  mean /= static_cast<double>(n);
  double rss0 = 0;
  for (double v : y) rss0 += (v - mean) * (v - mean);

  // From a tenth of a bin's spacing to three times the run: beyond that exp(-t/tau) is a line.
  const double tau_lo = std::max(1e-3, 0.5 * (t.size() > 1 ? t[1] - t[0] : 1.0)), tau_hi = 3.0 * T;
  constexpr int kGrid = 80;
  std::vector<double> grid(kGrid);
  int best = 0;
  double best_rss = std::numeric_limits<double>::infinity();
  for (int i = 0; i < kGrid; ++i) {
    grid[static_cast<std::size_t>(i)] = tau_lo * std::pow(tau_hi / tau_lo, static_cast<double>(i) / (kGrid - 1));
    const double rss = fit_at(t, y, grid[static_cast<std::size_t>(i)]).rss;
    if (rss < best_rss) {
      best_rss = rss;
      best = i;
    }
  }
  double lo = std::log(grid[static_cast<std::size_t>(std::max(0, best - 1))]);
  double hi = std::log(grid[static_cast<std::size_t>(std::min(kGrid - 1, best + 1))]);
  const double phi = 0.5 * (std::sqrt(5.0) - 1.0);
  double x1 = hi - phi * (hi - lo), x2 = lo + phi * (hi - lo);
  double f1 = fit_at(t, y, std::exp(x1)).rss, f2 = fit_at(t, y, std::exp(x2)).rss;
  for (int it = 0; it < 60; ++it) {
    if (f1 < f2) {
      hi = x2;
      x2 = x1;
      f2 = f1;
      x1 = hi - phi * (hi - lo);
      f1 = fit_at(t, y, std::exp(x1)).rss;
    } else {
      lo = x1;
      x1 = x2;
      f1 = f2;
      x2 = lo + phi * (hi - lo);
      f2 = fit_at(t, y, std::exp(x2)).rss;
    }
  }
  const double tau = std::exp(0.5 * (lo + hi));
  const LinearFit f = fit_at(t, y, tau);
  ch.amplitude = f.a;
  ch.time_constant_s = tau;
  const double dof = static_cast<double>(n) - 3.0;
  const double s2 = f.rss / dof;
  ch.residual_rms = std::sqrt(f.rss / static_cast<double>(n));
  ch.chi2_gain = s2 > 0 ? (rss0 - f.rss) / s2 : 0.0;
  ch.detected = ch.chi2_gain > chi2_threshold;
  ch.resolved = best < kGrid - 1 && tau < T;

  Eigen::Matrix3d N = Eigen::Matrix3d::Zero();
  for (std::size_t k = 0; k < n; ++k) {
    const double x = std::exp(-t[k] / tau);
    const Eigen::Vector3d J(1.0, x, f.a * t[k] / (tau * tau) * x);
    N += J * J.transpose();
  }
  const Eigen::Matrix3d cov = s2 * N.inverse();
  ch.amplitude_sigma = std::sqrt(std::max(0.0, cov(1, 1)));
  ch.time_constant_sigma_s = std::sqrt(std::max(0.0, cov(2, 2)));
  // Outside the band until |a| exp(-t/tau) = band.
  if (std::abs(f.a) > band) {
    const double L = std::log(std::abs(f.a) / band);
    ch.settle_time_s = tau * L;
    const Eigen::Vector3d g(0.0, tau / f.a, L);
    ch.settle_time_sigma_s = std::sqrt(std::max(0.0, g.dot(cov * g)));
  }
  deviation.resize(n);
  for (std::size_t k = 0; k < n; ++k) deviation[k] = y[k] - f.c;
  return ch;
}

}  // namespace

struct WarmUpEstimator::Impl {
  Options options;
  table_reference::SegmentFrames frames{{}};
  table_reference::FrameIntervals intervals;
  std::vector<Bin> bins;
  double dt_nominal_s;
  int gaps = 0;

  Impl(const RecordingMeta& m, Options o) : options(o), dt_nominal_s(1.0 / m.rate_hz) {
    if (!(options.bin_s > 0)) throw std::invalid_argument("warm-up: the bin length must be positive");
    std::vector<table_reference::SegmentFrames::Span> spans;
    for (const SegmentInfo& s : m.segments)
      if (s.kind == "static" || s.kind == "tilt") spans.push_back({s.t0_s, s.t1_s, false});
    std::sort(spans.begin(), spans.end(), [](const auto& a, const auto& b) { return a.t0_s < b.t0_s; });
    frames = table_reference::SegmentFrames(std::move(spans));
  }

  void push(const ImuFrame& f) {
    const auto iv = intervals.next(f);
    if (!iv || frames.assign(iv->t_prev_s, iv->t_s) < 0) return;
    if (iv->dt_s > 1.5 * dt_nominal_s || iv->dt_s <= 0) ++gaps;
    const double since_on = 0.5 * (iv->t_prev_s + iv->t_s) - options.power_on_s;
    if (since_on < 0) return;
    const auto k = static_cast<std::size_t>(since_on / options.bin_s);
    if (bins.size() <= k) bins.resize(k + 1);
    Bin& b = bins[k];
    if (!b.used) b.first_deg = f.table_deg;
    b.used = true;
    b.sum_dtheta_rad += f.dtheta_rad;
    b.sum_dv_mps += f.dv_mps;
    b.T_s += iv->dt_s;
    b.sum_t_dt += since_on * iv->dt_s;
  }
};

WarmUpEstimator::WarmUpEstimator(const RecordingMeta& meta, Options options)
    : impl_(std::make_unique<Impl>(meta, options)) {}
WarmUpEstimator::~WarmUpEstimator() = default;
void WarmUpEstimator::push(const ImuFrame& frame) { impl_->push(frame); }
int WarmUpEstimator::bins_seen() const {
  return static_cast<int>(std::count_if(impl_->bins.begin(), impl_->bins.end(), [](const Bin& b) { return b.used; }));
}

Result WarmUpEstimator::finish(const ImuModel& prior) const {
  const Options& o = impl_->options;
  Result out;
  out.model = prior;
  char buf[320];
  // Bins at least half covered by static frames, all at one orientation.
  std::vector<const Bin*> used;
  for (std::size_t k = 0; k < impl_->bins.size(); ++k) {
    const Bin& b = impl_->bins[k];
    if (!b.used || b.T_s < 0.5 * o.bin_s) continue;
    if (!used.empty() && (b.first_deg - used.front()->first_deg).cwiseAbs().maxCoeff() > 0.01)
      throw std::runtime_error("stage warm-up: the statics are at more than one orientation (the transient needs one "
                               "static from power-on; program 'warm-up' gives it)");
    used.push_back(&b);
    out.t_s.push_back(b.sum_t_dt / b.T_s);
  }
  constexpr std::size_t kMinBins = 30;
  if (used.size() < kMinBins) {
    std::snprintf(buf, sizeof buf,
                  "stage warm-up: %zu bins of %.0f s of static from power-on; the fit needs at least %zu (a static of "
                  "%.0f s or more; program 'warm-up' holds still for 2 h)",
                  used.size(), o.bin_s, kMinBins, static_cast<double>(kMinBins) * o.bin_s);
    throw std::runtime_error(buf);
  }
  out.duration_s = static_cast<double>(impl_->bins.size()) * o.bin_s;
  if (impl_->gaps > 0) {
    std::snprintf(buf, sizeof buf, "%d gaps in the frames of the static: the bins around them hold fewer frames", impl_->gaps);
    out.notes.emplace_back(buf);
  }

  TurnOnSection section = turn_on_of(prior).value_or(TurnOnSection{});
  TurnOnTerms sigma = section.sigma.value_or(TurnOnTerms{});
  static const char* const kAxes[3] = {"x", "y", "z"};
  for (int c = 0; c < 6; ++c) {
    const bool gyro = c < 3;
    const int j = c % 3;
    std::vector<double> y;
    y.reserve(used.size());
    for (const Bin* b : used) y.push_back(gyro ? b->sum_dtheta_rad[j] / b->T_s : b->sum_dv_mps[j] / b->T_s);
    const double band = gyro ? o.gyro_band_dph * units::kDphToRadps : o.accel_band_ug * kUgToMps2;
    Channel ch = fit_channel(out.t_s, y, band, o.detection_chi2, out.deviation[static_cast<std::size_t>(c)]);
    ch.gyro = gyro;
    ch.axis = j;
    Eigen::Vector3d& amp = gyro ? section.value.gyro_warm_up_radps : section.value.accel_warm_up_mps2;
    Eigen::Vector3d& tau = gyro ? section.value.gyro_time_constant_s : section.value.accel_time_constant_s;
    Eigen::Vector3d& amp_s = gyro ? sigma.gyro_warm_up_radps : sigma.accel_warm_up_mps2;
    Eigen::Vector3d& tau_s = gyro ? sigma.gyro_time_constant_s : sigma.accel_time_constant_s;
    if (ch.detected) {
      amp[j] = ch.amplitude;
      tau[j] = ch.time_constant_s;
      amp_s[j] = ch.amplitude_sigma;
      tau_s[j] = ch.time_constant_sigma_s;
      if (!ch.resolved) {
        std::snprintf(buf, sizeof buf,
                      "%s %s: the transient's time constant (%.0f s) is not shorter than the run (%.0f s): run longer "
                      "for its value",
                      gyro ? "gyro" : "accelerometer", kAxes[j], ch.time_constant_s, out.duration_s);
        out.notes.emplace_back(buf);
      }
    } else {
      amp[j] = tau[j] = amp_s[j] = tau_s[j] = 0.0;
      ch.settle_time_s = ch.settle_time_sigma_s = 0.0;
      std::snprintf(buf, sizeof buf, "%s %s: no warm-up transient above the noise (the fit took out %.1f residual "
                    "variances, %.0f needed)", gyro ? "gyro" : "accelerometer", kAxes[j], ch.chi2_gain, o.detection_chi2);
      out.notes.emplace_back(buf);
    }
    out.channels[static_cast<std::size_t>(c)] = ch;
  }
  section.sigma = sigma;
  set_turn_on(out.model, section);
  return out;
}

}  // namespace imucal::warm_up
