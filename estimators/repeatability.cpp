#include "estimators/repeatability.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <stdexcept>

#include "core/turn_on.hpp"
#include "core/units.hpp"
#include "estimators/least_squares.hpp"
#include "estimators/table_reference.hpp"

namespace imucal::repeatability {

namespace {

// The mean of a static's noise from the scatter of this many equal blocks of it.
constexpr int kBlocks = 10;

struct Static {
  std::string name;
  double t0_s = 0, t1_s = 0;
  int turn_on = 1;
  // Frames accumulated per block (by time within the static).
  std::array<Vector6d, kBlocks> sum = {};
  std::array<double, kBlocks> T_s = {};
  Eigen::Vector3d first_deg = Eigen::Vector3d::Zero();
  int frames = 0;
};

}  // namespace

struct RepeatabilityEstimator::Impl {
  std::vector<Static> statics;
  table_reference::SegmentFrames frames{{}};
  table_reference::FrameIntervals intervals;

  explicit Impl(const RecordingMeta& m) {
    std::vector<SegmentInfo> segments = m.segments;
    std::sort(segments.begin(), segments.end(), [](const SegmentInfo& a, const SegmentInfo& b) { return a.t0_s < b.t0_s; });
    int turn_on = 1;  // the power-on at the run's start
    for (const SegmentInfo& s : segments) {
      if (s.kind == "power-cycle") ++turn_on;
      if (s.kind == "static") {
        Static st;
        st.name = s.name;
        st.t0_s = s.t0_s;
        st.t1_s = s.t1_s;
        st.turn_on = turn_on;
        for (auto& v : st.sum) v.setZero();
        statics.push_back(st);
      }
    }
    std::vector<table_reference::SegmentFrames::Span> spans;
    for (const Static& s : statics) spans.push_back({s.t0_s, s.t1_s, false});
    frames = table_reference::SegmentFrames(std::move(spans));
  }

  void push(const ImuFrame& f) {
    const auto iv = intervals.next(f);
    if (!iv) return;
    const int i = frames.assign(iv->t_prev_s, iv->t_s);
    if (i < 0) return;
    Static& s = statics[static_cast<std::size_t>(i)];
    if (s.frames == 0) s.first_deg = f.table_deg;
    const double u = (0.5 * (iv->t_prev_s + iv->t_s) - s.t0_s) / (s.t1_s - s.t0_s);
    const auto b = static_cast<std::size_t>(std::clamp(static_cast<int>(u * kBlocks), 0, kBlocks - 1));
    s.sum[b].head<3>() += f.dtheta_rad;
    s.sum[b].tail<3>() += f.dv_mps;
    s.T_s[b] += iv->dt_s;
    ++s.frames;
  }
};

RepeatabilityEstimator::RepeatabilityEstimator(const RecordingMeta& meta) : impl_(std::make_unique<Impl>(meta)) {}
RepeatabilityEstimator::~RepeatabilityEstimator() = default;
void RepeatabilityEstimator::push(const ImuFrame& frame) { impl_->push(frame); }

int RepeatabilityEstimator::turn_ons_seen() const {
  std::vector<int> seen;
  for (const Static& s : impl_->statics)
    if (s.frames > 0 && std::find(seen.begin(), seen.end(), s.turn_on) == seen.end()) seen.push_back(s.turn_on);
  return static_cast<int>(seen.size());
}

namespace {

// The power-ons with a static long enough for its blocks, in order (their statics merged); the
// statics must be at one orientation.
std::vector<TurnOn> turn_ons_of(const std::vector<Static>& statics) {
  std::vector<TurnOn> turn_ons;
  const Static* first = nullptr;
  for (const Static& s : statics) {
    if (s.frames < 2 * kBlocks) continue;
    if (first && (s.first_deg - first->first_deg).cwiseAbs().maxCoeff() > 0.01)
      throw std::runtime_error("stage repeatability: the statics are at more than one orientation (the power-ons are "
                               "compared at one; program 'repeatability' gives them)");
    if (!first) first = &s;
    if (turn_ons.empty() || turn_ons.back().index != s.turn_on) {
      TurnOn t;
      t.index = s.turn_on;
      t.segment = s.name;
      t.t0_s = s.t0_s;
      turn_ons.push_back(t);
    }
  }
  if (turn_ons.size() < 3) {
    char buf[320];
    std::snprintf(buf, sizeof buf,
                  "stage repeatability: %zu power-on(s) with a static; the spread needs at least 3 (program "
                  "'repeatability' gives 8, 'repeatability-short' 6)",
                  turn_ons.size());
    throw std::runtime_error(buf);
  }
  return turn_ons;
}

// A power-on's mean of the six channels over its statics' blocks, and the mean's standard error.
void measure_turn_on(const std::vector<Static>& statics, TurnOn& t) {
  std::vector<Vector6d> block_means;
  Vector6d sum = Vector6d::Zero();
  double T = 0;
  for (const Static& s : statics) {
    if (s.turn_on != t.index || s.frames < 2 * kBlocks) continue;
    for (int b = 0; b < kBlocks; ++b) {
      if (s.T_s[static_cast<std::size_t>(b)] <= 0) continue;
      block_means.push_back(s.sum[static_cast<std::size_t>(b)] / s.T_s[static_cast<std::size_t>(b)]);
      sum += s.sum[static_cast<std::size_t>(b)];
      T += s.T_s[static_cast<std::size_t>(b)];
    }
  }
  t.duration_s = T;
  t.mean = sum / T;
  // The blocks are of nearly equal length: the standard error of their mean.
  Vector6d var = Vector6d::Zero();
  for (const Vector6d& m : block_means) var += (m - t.mean).cwiseAbs2();
  const auto n = static_cast<double>(block_means.size());
  t.mean_sigma = (var / (n - 1.0) / n).cwiseSqrt();
}

// Channel c's spread over the power-ons, the noise in it, and the repeatability with its
// chi-square intervals.
Channel channel_of(int c, const std::vector<TurnOn>& turn_ons) {
  const auto N = static_cast<double>(turn_ons.size());
  Channel ch;
  ch.gyro = c < 3;
  ch.axis = c % 3;
  double mean = 0, noise2 = 0;
  for (const TurnOn& t : turn_ons) {
    mean += t.mean[c];
    noise2 += t.mean_sigma[c] * t.mean_sigma[c];
  }
  mean /= N;
  noise2 /= N;
  double s2 = 0;
  for (const TurnOn& t : turn_ons) s2 += (t.mean[c] - mean) * (t.mean[c] - mean);
  s2 /= N - 1.0;
  ch.spread = std::sqrt(s2);
  ch.noise = std::sqrt(noise2);
  // (N - 1) s^2 / sigma^2 is chi-square with N - 1 degrees of freedom: the spread's intervals,
  // then the noise taken out of each end.
  const double dof = N - 1.0;
  const auto spread_at = [&](double z) { return ch.spread * std::sqrt(dof / least_squares::chi_square_quantile(dof, -z)); };
  const auto less_noise = [&](double s) { return std::sqrt(std::max(0.0, s * s - noise2)); };
  ch.repeatability = less_noise(ch.spread);
  ch.lo68 = less_noise(spread_at(-1.0));
  ch.hi68 = less_noise(spread_at(1.0));
  ch.lo997 = less_noise(spread_at(-3.0));
  ch.hi997 = less_noise(spread_at(3.0));
  ch.repeatability_sigma = 0.5 * (ch.hi68 - ch.lo68);
  return ch;
}

}  // namespace

Result RepeatabilityEstimator::finish(const ImuModel& prior) const {
  Result out;
  out.model = prior;
  out.turn_ons = turn_ons_of(impl_->statics);
  for (TurnOn& t : out.turn_ons) measure_turn_on(impl_->statics, t);
  TurnOnSection section = turn_on_of(prior).value_or(TurnOnSection{});
  TurnOnTerms sigma = section.sigma.value_or(TurnOnTerms{});
  static const char* const kAxes[3] = {"x", "y", "z"};
  for (int c = 0; c < 6; ++c) {
    Channel& ch = out.channels[static_cast<std::size_t>(c)];
    ch = channel_of(c, out.turn_ons);
    if (ch.repeatability == 0.0) {
      char buf[320];
      std::snprintf(buf, sizeof buf,
                    "%s %s: the power-ons differ by no more than the noise within the statics (repeatability below "
                    "%.3g %s at 68 %%)",
                    ch.gyro ? "gyro" : "accelerometer", kAxes[ch.axis],
                    ch.hi68 * (ch.gyro ? units::kRadpsToDph : 1e6 / units::kStandardGravity_mps2), ch.gyro ? "deg/h" : "ug");
      out.notes.emplace_back(buf);
    }
    Eigen::Vector3d& rep = ch.gyro ? section.value.gyro_repeatability_radps : section.value.accel_repeatability_mps2;
    Eigen::Vector3d& rep_s = ch.gyro ? sigma.gyro_repeatability_radps : sigma.accel_repeatability_mps2;
    rep[ch.axis] = ch.repeatability;
    rep_s[ch.axis] = ch.repeatability_sigma;
  }
  section.sigma = sigma;
  set_turn_on(out.model, section);
  return out;
}

}  // namespace imucal::repeatability
