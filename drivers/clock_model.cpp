#include "drivers/clock_model.hpp"

#include <algorithm>
#include <cmath>

namespace imucal::drivers {

void ClockFit::clear() noexcept {
  blocks_.clear();
  have_current_ = false;
  have_model_ = false;
  a_ns_ = 0.0;
  b_ = 1.0;
  residual_rms_ns_ = 0.0;
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
  return s;
}

void ClockFit::add(std::int64_t device_ns, std::int64_t host_ns, std::int64_t key) {
  if (have_model_) {
    const double r = static_cast<double>(host_ns - ref_host_ns_) - model_at(device_ns);
    // A jump of either clock (device reboot, host clock step) or a device time running backwards
    // makes the old points meaningless.
    const bool backwards = have_current_ && device_ns < current_.device_ns;
    if (std::fabs(r) > static_cast<double>(config_.reset_threshold_ns) || backwards) {
      clear();
      ++resets_;
    }
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

void ClockFit::refit() noexcept {
  // Points: completed blocks plus the block in progress.
  const std::size_t n = blocks_.size() + (have_current_ ? 1 : 0);
  if (n == 0) return;
  auto point = [&](std::size_t i) -> const Point& { return i < blocks_.size() ? blocks_[i] : current_; };
  double mx = 0.0, my = 0.0;
  for (std::size_t i = 0; i < n; ++i) {
    mx += static_cast<double>(point(i).device_ns - ref_device_ns_);
    my += static_cast<double>(point(i).host_ns - ref_host_ns_);
  }
  mx /= static_cast<double>(n);
  my /= static_cast<double>(n);
  double sxx = 0.0, sxy = 0.0;
  for (std::size_t i = 0; i < n; ++i) {
    const double dx = static_cast<double>(point(i).device_ns - ref_device_ns_) - mx;
    const double dy = static_cast<double>(point(i).host_ns - ref_host_ns_) - my;
    sxx += dx * dx;
    sxy += dx * dy;
  }
  // Drift needs a baseline: with less than one block span of device time keep the rate at 1.
  double b = 1.0;
  const std::int64_t span_ns = point(n - 1).device_ns - point(0).device_ns;
  if (n >= 3 && sxx > 0.0 && span_ns >= 2 * config_.block_span_ns) {
    b = sxy / sxx;
    // A drift beyond 1000 ppm is not a clock: keep the nominal rate rather than extrapolate.
    if (!(std::fabs(b - 1.0) < 1e-3)) b = 1.0;
  }
  double a = my - b * mx;
  double min_r = 0.0, sum_r2 = 0.0;
  for (std::size_t i = 0; i < n; ++i) {
    const double r = static_cast<double>(point(i).host_ns - ref_host_ns_) -
                     (a + b * static_cast<double>(point(i).device_ns - ref_device_ns_));
    min_r = i == 0 ? r : std::min(min_r, r);
    sum_r2 += r * r;
  }
  if (config_.lower_envelope) {
    // Delays are never negative: rest the line on the lowest point.
    a += min_r;
    sum_r2 = 0.0;
    for (std::size_t i = 0; i < n; ++i) {
      const double r = static_cast<double>(point(i).host_ns - ref_host_ns_) -
                       (a + b * static_cast<double>(point(i).device_ns - ref_device_ns_));
      sum_r2 += r * r;
    }
  }
  a_ns_ = a;
  b_ = b;
  residual_rms_ns_ = std::sqrt(sum_r2 / static_cast<double>(n));
  have_model_ = true;
}

}  // namespace imucal::drivers
