#include "estimators/noise.hpp"

#include <algorithm>
#include <cmath>
#include <complex>
#include <cstdio>
#include <functional>

#include <Eigen/Dense>
#include <nlohmann/json.hpp>
#include <unsupported/Eigen/FFT>

#include "core/units.hpp"

namespace imucal::noise {

std::vector<double> overlapping_adev(const std::vector<double>& rate, double dt_s, const std::vector<long>& m_list) {
  std::vector<double> theta(rate.size() + 1, 0.0);
  for (std::size_t k = 0; k < rate.size(); ++k) theta[k + 1] = theta[k] + rate[k] * dt_s;
  std::vector<double> out;
  const auto N = static_cast<long>(theta.size());
  for (long m : m_list) {
    double sum = 0;
    long terms = 0;
    for (long k = 0; k + 2 * m < N; ++k) {
      const double d = theta[static_cast<std::size_t>(k + 2 * m)] - 2 * theta[static_cast<std::size_t>(k + m)] +
                       theta[static_cast<std::size_t>(k)];
      sum += d * d;
      ++terms;
    }
    const double tau = static_cast<double>(m) * dt_s;
    out.push_back(terms > 0 ? std::sqrt(sum / (2.0 * tau * tau * static_cast<double>(terms))) : 0.0);
  }
  return out;
}

NoiseAnalyzer::NoiseAnalyzer(const RecordingMeta& meta, const Options& options) : meta_(meta), options_(options) {
  // A bin is never shorter than one sample: slow recordings are analysed at their own rate.
  options_.bin_s = std::max(options.bin_s, 1.0 / meta.rate_hz);
  for (const SegmentInfo& s : meta.segments)
    if ((s.kind == "static" || s.kind == "tilt") && s.t1_s - s.t0_s >= options.min_static_s) statics_.push_back(s);
  std::sort(statics_.begin(), statics_.end(), [](const auto& a, const auto& b) { return a.t0_s < b.t0_s; });
}

void NoiseAnalyzer::close_bin() {
  for (std::size_t c = 0; c < 6; ++c) {
    runs_.back().rate[c].push_back(bin_sum_[c] / bin_T_);
    bin_sum_[c] = 0;
  }
  bin_T_ = 0;
}

void NoiseAnalyzer::push(const ImuFrame& f) {
  const double dt = have_prev_ ? static_cast<double>(f.t_ns - prev_t_ns_) * 1e-9 : 0.0;
  const bool gap = have_prev_ && (dt > 1.5 / meta_.rate_hz || dt <= 0);
  prev_t_ns_ = f.t_ns;
  const bool first = !have_prev_;
  have_prev_ = true;
  // Membership on the nanosecond clock: a frame ending exactly at a static's start covers the move.
  auto ns = [](double s) { return std::llround(s * 1e9); };
  while (next_ < statics_.size() && f.t_ns > ns(statics_[next_].t1_s)) ++next_;
  const bool in_static = next_ < statics_.size() && f.t_ns > ns(statics_[next_].t0_s) && !first;
  if (!in_static || gap) {
    in_run_ = false;
    return;
  }
  if (!in_run_ || run_segment_ != statics_[next_].name) {
    // A new contiguous run: the Allan clusters never straddle a move or a gap.
    runs_.emplace_back();
    in_run_ = true;
    run_segment_ = statics_[next_].name;
    bin_sum_.fill(0);
    bin_T_ = 0;
  }
  for (int j = 0; j < 3; ++j) {
    bin_sum_[static_cast<std::size_t>(j)] += f.dtheta_rad[j];
    bin_sum_[static_cast<std::size_t>(3 + j)] += f.dv_mps[j];
  }
  bin_T_ += dt;
  if (bin_T_ >= options_.bin_s * (1 - 1e-9)) close_bin();
}

namespace {

using Series = std::vector<std::reference_wrapper<const std::vector<double>>>;  // one channel's runs

// Cluster sizes spaced about 8 per decade, up to a third of the longest run.
std::vector<long> cluster_sizes(std::size_t longest) {
  std::vector<long> m_list;
  for (double m = 1; m <= static_cast<double>(longest) / 3.0; m *= 1.33) {
    const long mi = std::lround(m);
    if (m_list.empty() || mi != m_list.back()) m_list.push_back(mi);
  }
  return m_list;
}

// The overlapping Allan deviation over every run, each cluster size's terms pooled.
void allan_curve(const Series& runs, double dt, const std::vector<long>& m_list, ChannelNoise& ch) {
  std::vector<double> sum(m_list.size(), 0.0), terms(m_list.size(), 0.0);
  for (const std::vector<double>& y : runs) {
    const std::vector<double> adev = overlapping_adev(y, dt, m_list);
    for (std::size_t i = 0; i < m_list.size(); ++i) {
      const double n_terms = static_cast<double>(y.size()) + 1.0 - 2.0 * static_cast<double>(m_list[i]);
      if (n_terms <= 0) continue;
      sum[i] += adev[i] * adev[i] * n_terms;
      terms[i] += n_terms;
    }
  }
  for (std::size_t i = 0; i < m_list.size(); ++i)
    if (terms[i] > 0) {
      ch.tau_s.push_back(static_cast<double>(m_list[i]) * dt);
      ch.adev.push_back(std::sqrt(sum[i] / terms[i]));
    }
}

// White noise: sigma(tau) sqrt(tau) where the curve still falls as 1/sqrt(tau) (tau <= 1 s).
void white_noise(ChannelNoise& ch) {
  std::vector<double> white;
  for (std::size_t i = 0; i < ch.tau_s.size(); ++i)
    if (ch.tau_s[i] <= 1.0) white.push_back(ch.adev[i] * std::sqrt(ch.tau_s[i]));
  if (!white.empty()) {
    std::nth_element(white.begin(), white.begin() + static_cast<long>(white.size() / 2), white.end());
    ch.white = white[white.size() / 2];
  }
}

// Bias instability: fit AVAR = a/tau + b + c tau (white, flicker floor, rate random walk) with
// non-negative terms, each point weighted by its relative precision (about sqrt(m/N)), and read
// the floor from b: a minimum of the curve would be pulled down by the scatter of the points.
double bias_instability(const ChannelNoise& ch, double total_static_s) {
  const auto n = static_cast<Eigen::Index>(ch.tau_s.size());
  Eigen::MatrixXd A(n, 3);
  Eigen::VectorXd y(n), wt(n);
  for (Eigen::Index i = 0; i < n; ++i) {
    const double tau = ch.tau_s[static_cast<std::size_t>(i)], av = ch.adev[static_cast<std::size_t>(i)];
    A.row(i) << 1.0 / tau, 1.0, tau;
    y(i) = av * av;
    const double clusters = std::max(1.0, total_static_s / tau);
    wt(i) = clusters / (y(i) * y(i));
  }
  double best_cost = 1e300;
  Eigen::Vector3d best = Eigen::Vector3d::Zero();
  for (int mask = 1; mask < 8; ++mask) {
    std::vector<Eigen::Index> cols;
    for (Eigen::Index k = 0; k < 3; ++k)
      if (mask & (1 << k)) cols.push_back(k);
    Eigen::MatrixXd As(n, static_cast<Eigen::Index>(cols.size()));
    for (std::size_t k = 0; k < cols.size(); ++k) As.col(static_cast<Eigen::Index>(k)) = A.col(cols[k]);
    const Eigen::MatrixXd N = As.transpose() * wt.asDiagonal() * As;
    const Eigen::VectorXd sol = N.ldlt().solve(As.transpose() * wt.asDiagonal() * y);
    if ((sol.array() < 0).any()) continue;
    const Eigen::VectorXd res = y - As * sol;
    const double cost = res.dot(wt.asDiagonal() * res);
    if (cost < best_cost) {
      best_cost = cost;
      best.setZero();
      for (std::size_t k = 0; k < cols.size(); ++k) best[cols[k]] = sol[static_cast<Eigen::Index>(k)];
    }
  }
  return std::sqrt(best[1]) / 0.664;
}

// Welch PSD with a Hann window over segments of 1024 bins (10 s at 0.01 s), half overlapping.
void welch_psd(const Series& runs, double dt, ChannelNoise& ch) {
  constexpr std::size_t L = 1024;
  Eigen::FFT<double> fft;
  std::vector<double> psd(L / 2 + 1, 0.0);
  int segments = 0;
  std::vector<double> w(L);
  double w2 = 0;
  for (std::size_t k = 0; k < L; ++k) {
    w[k] = 0.5 - 0.5 * std::cos(2 * units::kPi * static_cast<double>(k) / static_cast<double>(L));
    w2 += w[k] * w[k];
  }
  for (const std::vector<double>& y : runs) {
    for (std::size_t s = 0; s + L <= y.size(); s += L / 2) {
      double mean = 0;
      for (std::size_t k = 0; k < L; ++k) mean += y[s + k];
      mean /= static_cast<double>(L);
      std::vector<double> x(L);
      for (std::size_t k = 0; k < L; ++k) x[k] = (y[s + k] - mean) * w[k];
      std::vector<std::complex<double>> X;
      fft.fwd(X, x);
      for (std::size_t k = 0; k <= L / 2; ++k) psd[k] += std::norm(X[k]) * 2.0 * dt / w2;
      ++segments;
    }
  }
  if (segments > 0)
    for (std::size_t k = 1; k <= L / 2; ++k) {
      ch.psd_freq_hz.push_back(static_cast<double>(k) / (static_cast<double>(L) * dt));
      ch.psd.push_back(psd[k] / segments);
    }
}

}  // namespace

Result NoiseAnalyzer::finish() const {
  Result r;
  std::size_t longest = 0;
  for (const Run& run : runs_) {
    longest = std::max(longest, run.rate[0].size());
    r.total_static_s += static_cast<double>(run.rate[0].size()) * options_.bin_s;
  }
  r.longest_static_s = static_cast<double>(longest) * options_.bin_s;
  if (longest < 16) throw std::runtime_error("stage noise: no static interval long enough for noise analysis");
  const std::vector<long> m_list = cluster_sizes(longest);
  const double dt = options_.bin_s;
  for (std::size_t c = 0; c < 6; ++c) {
    ChannelNoise& ch = r.channel[c];
    Series runs;
    for (const Run& run : runs_) runs.emplace_back(run.rate[c]);
    allan_curve(runs, dt, m_list, ch);
    white_noise(ch);
    if (r.longest_static_s >= options_.min_bias_instability_static_s) ch.bias_instability = bias_instability(ch, r.total_static_s);
    welch_psd(runs, dt, ch);
  }
  char buf[200];
  std::snprintf(buf, sizeof buf, "stage noise: %zu static runs, %.0f s in all, longest %.0f s%s", runs_.size(),
                r.total_static_s, r.longest_static_s,
                r.longest_static_s >= options_.min_bias_instability_static_s
                    ? ""
                    : " (too short for bias instability: record the 2 h noise program)");
  r.notes.push_back(buf);
  return r;
}

ImuModel Result::apply(const ImuModel& model) const {
  ImuModel m = model;
  m.gyro.noise.arw_rad_rts = (channel[0].white + channel[1].white + channel[2].white) / 3.0;
  m.accel.noise.vrw_mps_rts = (channel[3].white + channel[4].white + channel[5].white) / 3.0;
  if (channel[0].bias_instability > 0) {
    m.gyro.noise.bias_instability_radps =
        (channel[0].bias_instability + channel[1].bias_instability + channel[2].bias_instability) / 3.0;
    m.accel.noise.bias_instability_mps2 =
        (channel[3].bias_instability + channel[4].bias_instability + channel[5].bias_instability) / 3.0;
  }
  return m;
}

std::string Result::curves_json() const {
  nlohmann::json j;
  const char* names[6] = {"gyro_x", "gyro_y", "gyro_z", "accel_x", "accel_y", "accel_z"};
  for (std::size_t c = 0; c < 6; ++c) {
    // Gyro curves in deg/h, accelerometer curves in m/s^2: the units people read plots in.
    const double s = c < 3 ? units::kRadpsToDph : 1.0;
    std::vector<double> adev, psd;
    for (double v : channel[c].adev) adev.push_back(v * s);
    for (double v : channel[c].psd) psd.push_back(v * s * s);
    j[names[c]] = {{"tau_s", channel[c].tau_s},
                   {"adev", adev},
                   {"psd_freq_hz", channel[c].psd_freq_hz},
                   {"psd", psd},
                   {"unit", c < 3 ? "deg/h" : "m/s^2"}};
  }
  return j.dump();
}

}  // namespace imucal::noise
