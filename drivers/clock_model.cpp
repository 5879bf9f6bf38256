#include "drivers/clock_model.hpp"

#include <algorithm>
#include <cmath>
#include <utility>
#include <vector>

namespace imucal::drivers {

void ClockFit::clear() noexcept {
  blocks_.clear();
  have_current_ = false;
  have_model_ = false;
  a_ns_ = 0.0;
  b_ = 1.0;
  residual_rms_ns_ = 0.0;
  late_ = false;
}

double ClockFit::model_at(std::int64_t device_ns) const noexcept {
  return a_ns_ + b_ * static_cast<double>(device_ns - ref_device_ns_);
}

std::int64_t ClockFit::map(std::int64_t device_ns) const noexcept {
  if (!have_model_) return device_ns;
  return ref_host_ns_ + std::llround(model_at(device_ns));
}

ClockModelState ClockFit::state() const noexcept {
  ClockModelState s;
  s.valid = have_model_;
  s.drift_ppm = (b_ - 1.0) * 1e6;
  s.residual_rms_ns = residual_rms_ns_;
  s.points = blocks_.size() + (have_current_ ? 1 : 0);
  s.resets = resets_;
  return s;
}

bool ClockFit::jumped(std::int64_t device_ns, std::int64_t host_ns, std::int64_t key) noexcept {
  // A device time running backwards: the device restarted its clock.
  if (have_current_ && device_ns < current_.device_ns) return true;
  const double r = static_cast<double>(host_ns - ref_host_ns_) - model_at(device_ns);
  const auto threshold = static_cast<double>(config_.reset_threshold_ns);
  if (!config_.lower_envelope) return std::fabs(r) > threshold + 0.5 * static_cast<double>(key);
  if (r < -threshold) return true;  // earlier than the model: no delay does that
  if (r <= threshold) {
    late_ = false;
    return false;
  }
  if (!late_) {
    late_ = true;
    late_since_device_ns_ = device_ns;
  }
  return device_ns - late_since_device_ns_ >= config_.late_confirm_ns;
}

void ClockFit::add(std::int64_t device_ns, std::int64_t host_ns, std::int64_t key) {
  if (have_model_ && jumped(device_ns, host_ns, key)) {
    clear();
    ++resets_;
  }
  if (!have_model_) {
    ref_device_ns_ = device_ns;
    ref_host_ns_ = host_ns;
  }
  if (!have_current_) {
    current_ = {device_ns, host_ns, key};
    have_current_ = true;
    block_start_ns_ = device_ns;
    refit();
    return;
  }
  if (device_ns - block_start_ns_ >= config_.block_span_ns) {
    blocks_.push_back(current_);
    while (blocks_.size() > config_.window_blocks) blocks_.pop_front();
    current_ = {device_ns, host_ns, key};
    block_start_ns_ = device_ns;
    refit();
    return;
  }
  if (key < current_.key) {
    current_ = {device_ns, host_ns, key};
    // Early on the model rests on very few points: follow every improvement. Later the model
    // changes only once per block, so that consecutive sample times stay smooth.
    if (blocks_.size() < 2) refit();
  }
}

namespace {

// The line under every point whose value at x_mean is highest: the edge of the points' lower
// convex hull above x_mean (it minimises the sum of the non-negative residuals). Points sorted by
// x; false when no edge spans x_mean.
bool lower_hull_line(const std::vector<std::pair<double, double>>& xz, double x_mean, double& a, double& c) {
  std::vector<std::pair<double, double>> hull;
  for (const auto& p : xz) {
    while (hull.size() >= 2) {
      const auto& o = hull[hull.size() - 2];
      const auto& q = hull.back();
      const double cross = (q.first - o.first) * (p.second - o.second) - (q.second - o.second) * (p.first - o.first);
      if (cross > 0.0) break;  // o -> q -> p turns left: q stays on the lower hull
      hull.pop_back();
    }
    hull.push_back(p);
  }
  for (std::size_t i = 0; i + 1 < hull.size(); ++i) {
    const auto& p = hull[i];
    const auto& q = hull[i + 1];
    if (p.first <= x_mean && x_mean <= q.first && q.first > p.first) {
      c = (q.second - p.second) / (q.first - p.first);
      a = p.second - c * p.first;
      return true;
    }
  }
  return false;
}

// The value a tenth of the way up `v` (the lower edge of what the prompt points reach).
template <class T>
T lowest_tenth(std::vector<T> v) {
  const auto q = v.begin() + static_cast<std::ptrdiff_t>(v.size() / 10);
  std::nth_element(v.begin(), q, v.end());
  return *q;
}

// Weighted least squares z = a + c x (weight 0 leaves a point out); false without a baseline.
bool least_squares_line(const std::vector<std::pair<double, double>>& xz, const std::vector<double>& weight, double& a,
                        double& c) {
  double n = 0.0, mx = 0.0, mz = 0.0;
  int used = 0;
  for (std::size_t i = 0; i < xz.size(); ++i) {
    if (!(weight[i] > 0.0)) continue;
    ++used;
    n += weight[i];
    mx += weight[i] * xz[i].first;
    mz += weight[i] * xz[i].second;
  }
  if (used < 2) return false;
  mx /= n;
  mz /= n;
  double sxx = 0.0, sxz = 0.0;
  for (std::size_t i = 0; i < xz.size(); ++i) {
    sxx += weight[i] * (xz[i].first - mx) * (xz[i].first - mx);
    sxz += weight[i] * (xz[i].first - mx) * (xz[i].second - mz);
  }
  if (!(sxx > 0.0)) return false;
  c = sxz / sxx;
  a = mz - c * mx;
  return true;
}

}  // namespace

void ClockFit::refit() noexcept {
  // Points: the completed blocks, each its best observation; while fewer than two are complete,
  // the block in progress too (its best so far). Once two are, the block in progress is left out:
  // its point is whatever came first in it, and at the end of the window it has the most
  // leverage on the line (one slow table read at a block's start moved the model by 500 us for
  // the whole block).
  const bool with_current = have_current_ && blocks_.size() < 2;
  const std::size_t n = blocks_.size() + (with_current ? 1 : 0);
  if (n == 0) return;
  auto point = [&](std::size_t i) -> const Point& { return i < blocks_.size() ? blocks_[i] : current_; };
  // Fitted in (x, z) = (device, host - device) relative to the reference, ns: z = a + c x with
  // b = 1 + c. z stays within milliseconds where host itself runs to seconds, so the products
  // of the hull and the sums of the least squares keep their precision.
  // Round trips bound each point's error by half of theirs: weighted by the inverse square (a
  // block whose only read so far was held up by a loaded host barely moves the line). Receive
  // stamps: every point alike, the late ones left out below.
  std::vector<double> weight(n, 1.0);
  if (!config_.lower_envelope)
    for (std::size_t i = 0; i < n; ++i) {
      const double half_ns = std::max(0.5 * static_cast<double>(point(i).key), static_cast<double>(config_.round_trip_floor_ns));
      weight[i] = 1.0 / (half_ns * half_ns);
    }
  std::vector<std::pair<double, double>> xz(n);
  double mx = 0.0, mz = 0.0, sum_w = 0.0;
  for (std::size_t i = 0; i < n; ++i) {
    const double x = static_cast<double>(point(i).device_ns - ref_device_ns_);
    xz[i] = {x, static_cast<double>(point(i).host_ns - ref_host_ns_) - x};
    mx += xz[i].first;
    mz += weight[i] * xz[i].second;
    sum_w += weight[i];
  }
  mx /= static_cast<double>(n);
  mz /= sum_w;  // weighted: the offset when there is no baseline for a drift
  // Drift needs a baseline: with less than two block spans of device time keep the rate at 1.
  const std::int64_t span_ns = point(n - 1).device_ns - point(0).device_ns;
  const bool fit_drift = n >= 3 && span_ns >= 2 * config_.block_span_ns;
  double a = 0.0, c = 0.0;
  bool fitted = false;
  if (fit_drift && config_.lower_envelope && lower_hull_line(xz, mx, a, c)) {
    // The prompt points: those within prompt_tolerance_ns of the lowest tenth of the heights
    // above the envelope. Blocks whose every observation came late (a sender or host loaded for a
    // while) lie further up and are left out; the line through the rest uses many points, where
    // the envelope's own edge rests on two, which may be rare early ones (a simulated IMU reached
    // its floor once in a few seconds, 60 us under the usual, and the edge between two such
    // points moved the drift by 13 ppm over 6 s).
    std::vector<double> height(n);
    for (std::size_t i = 0; i < n; ++i) height[i] = xz[i].second - (a + c * xz[i].first);
    const double limit = lowest_tenth(height) + static_cast<double>(config_.prompt_tolerance_ns);
    for (std::size_t i = 0; i < n; ++i) weight[i] = height[i] <= limit ? 1.0 : 0.0;
  }
  if (fit_drift && !config_.lower_envelope) {
    // The prompt round trips: within twice prompt_tolerance_ns of the lowest tenth's. A block
    // whose every read was held up by the host (a loaded machine) is left out, as a late block of
    // receive stamps is above: its weight alone still let it tilt the line by 100 us.
    std::vector<std::int64_t> keys(n);
    for (std::size_t i = 0; i < n; ++i) keys[i] = point(i).key;
    const std::int64_t limit = lowest_tenth(std::move(keys)) + 2 * config_.prompt_tolerance_ns;
    for (std::size_t i = 0; i < n; ++i)
      if (point(i).key > limit) weight[i] = 0.0;
  }
  if (fit_drift) fitted = least_squares_line(xz, weight, a, c);
  // A drift beyond 1000 ppm is not a clock: keep the nominal rate rather than extrapolate.
  if (!fitted || !(std::fabs(c) < 1e-3)) {
    c = 0.0;
    a = mz;
  }
  if (config_.lower_envelope) {
    // Delays are never negative: rest the line on the lowest point.
    double lowest = xz[0].second - (a + c * xz[0].first);
    for (const auto& [x, z] : xz) lowest = std::min(lowest, z - (a + c * x));
    a += lowest;
  }
  double sum_r2 = 0.0;
  for (const auto& [x, z] : xz) sum_r2 += (z - a - c * x) * (z - a - c * x);
  a_ns_ = a;
  b_ = 1.0 + c;
  residual_rms_ns_ = std::sqrt(sum_r2 / static_cast<double>(n));
  have_model_ = true;
}

}  // namespace imucal::drivers
